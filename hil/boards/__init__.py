"""Board files: what a controller board takes (SPEC's standard parameters, its own vendor
parameters) and what the bench pushes to it, apart from the bench profile's physics."""
from hil.boards.board_file import BoardFile, Setting, load_board, load_board_or_spec, spec_board
from hil.boards.standard import REQUIRED_PARAMS, STANDARD_PARAMS, ParamSpec

__all__ = ["BoardFile", "ParamSpec", "REQUIRED_PARAMS", "STANDARD_PARAMS", "Setting",
           "load_board", "load_board_or_spec", "spec_board"]
