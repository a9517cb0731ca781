"""Configuration files: the one layer that reads YAML written by people and checks it.

Bench profiles (plant_rt) and test plans (hil.plans) both load through here, so every bad
value is reported the same way, with the file, the line and the key:

- `source`: safe YAML loading that keeps the line of every key (`load_yaml`, `ConfigError`);
- `fields`: parameter fields declared on dataclasses with bounds (`param`, `coerce`);
- `schema`: structure checks, declared as JSON Schema and run on a located document
  (`SchemaChecker`); a parameter dataclass gives its schema with `dataclass_schema`;
- `dataclass_methods`: the standard dataclass decorator without compiled __repr__, __eq__ and
  __hash__ (the start-up of every class the bench imports).

It knows nothing of motors or boards: the physics and the bench both sit above it.
"""
from configfile.source import ConfigError, KeyPath, YamlDocument, format_key, load_yaml, parse_yaml

__all__ = ["ConfigError", "KeyPath", "YamlDocument", "format_key", "load_yaml", "parse_yaml"]
