"""pytest integration: `pytest test_plans/` runs every plan, one test item per check.

Collection: a ``*.yaml`` / ``*.yml`` file below a directory named in the ini
option ``hil_plan_dirs`` (default ``test_plans``) that looks like a plan (a
mapping with ``name`` or ``steps``; see hil.plans.format.looks_like_plan) becomes a
`PlanFile`. A plan that does not validate is a collection error carrying the
ConfigError (file, line, key, what was expected).

Items: ``<file>::run`` (the plan ran to its end: fails on ERROR, TIMEOUT or
ABORTED with the reason) and then ``<file>::<check name>`` for every check,
in plan order. One item per check, rather than one per plan with
sub-results, because that is what CI systems display and count: each check
becomes its own line in the JUnit output of ``pytest --junitxml`` with its
measured value and limits (as user properties), exactly like `hil run`'s
own junit.xml, and ``-k`` selects checks by name. The plan runs once per
file, on the first item that needs it; the other items read its result.
Selecting a single check still runs the whole plan (its checks need the
whole recording).

Options: ``--hil-link``, ``--hil-mode`` (default: the plan's, else the
runner's) and ``--hil-out DIR`` (MCAP log and reports per plan in
DIR/<plan>/, written by hil.run.runner.run_plan).

Fixture ``bench``: a running bench session (hil.run.runner.Bench) for
acceptance tests written in Python when YAML is not enough; see docs/plans.md.

hil.run.runner is imported lazily, so this module imports without it.
"""
from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import pytest

from hil.plans.outcome import CheckResult, Outcome, PlanResult
from configfile.source import ConfigError


class HilMarginalWarning(UserWarning):
    """A check passed within its marginal band."""


class HilCheckFailure(Exception):
    """A check (or a plan) that did not pass; its message is the whole report."""


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("hil", "hil-bench test plans")
    group.addoption("--hil-link", default=None,
                    help="board link for plans and the bench fixture (default: the plan's, else stub)")
    group.addoption("--hil-mode", default=None, choices=("lockstep", "realtime"),
                    help="clock (default: the plan's, else lockstep)")
    group.addoption("--hil-out", default=None, type=Path,
                    help="write each plan's log and reports into DIR/<plan>/")
    parser.addini("hil_plan_dirs", "names of directories whose YAML files are test plans",
                  type="args", default=["test_plans"])


def _is_plan_file(file_path: Path, config: pytest.Config) -> bool:
    if file_path.suffix not in (".yaml", ".yml"):
        return False
    dirs = set(config.getini("hil_plan_dirs"))
    # Directory names below the rootdir only: a checkout that happens to live
    # under a folder named test_plans must not turn all its YAML into plans.
    try:
        parts = file_path.parent.relative_to(config.rootpath).parts
    except ValueError:
        parts = file_path.parent.parts
    if not dirs.intersection(parts):
        return False
    from hil.plans.format import looks_like_plan

    return looks_like_plan(file_path)


def pytest_collect_file(parent: pytest.Collector, file_path: Path):
    if _is_plan_file(file_path, parent.config):
        return PlanFile.from_parent(parent, path=file_path)
    return None


class PlanFile(pytest.File):
    """One plan file: validates it, yields its items, runs it once on demand."""

    def collect(self):
        from hil.plans.format import load_plan

        try:
            self.plan = load_plan(self.path)
        except ConfigError as exc:
            raise self.CollectError(f"invalid plan: {exc}") from None
        self._outcomes: dict[Any, tuple[PlanResult, Any] | BaseException] = {}
        # A plan that lists several profiles is run on each: its items carry the profile.
        profiles = list(self.plan.profiles) or [None]
        for ref in profiles:
            tag = f"[{ref.label}]" if len(profiles) > 1 else ""
            yield PlanItem.from_parent(self, name=f"run{tag}", profile=ref)
            for check in self.plan.checks:
                yield CheckItem.from_parent(self, name=f"{check.name}{tag}", check_name=check.name,
                                            line=check.line, profile=ref)

    def result(self, profile=None) -> PlanResult:
        """The plan's result on `profile`, running it on the first call."""
        key = None if profile is None else profile.label
        if key not in self._outcomes:
            self._outcomes[key] = self._run(profile)
        outcome = self._outcomes[key]
        if isinstance(outcome, BaseException):
            raise HilCheckFailure(f"{self.path}: the plan could not run: "
                                  f"{type(outcome).__name__}: {outcome}")
        return outcome[0]

    def _run(self, profile):
        from hil.run.runner import run_plan

        opt = self.config.getoption
        try:
            # With out_dir, run_plan writes the log and the reports into out_dir/<plan>/.
            return run_plan(self.plan, link=opt("--hil-link"), mode=opt("--hil-mode"),
                            out_dir=opt("--hil-out"), profile=profile)
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception as exc:  # noqa: BLE001 - every item of this plan reports it
            return exc


class _HilItem(pytest.Item):
    def repr_failure(self, excinfo, style=None):
        if isinstance(excinfo.value, HilCheckFailure):
            return str(excinfo.value)
        return super().repr_failure(excinfo, style)

    def reportinfo(self):
        return self.path, getattr(self, "line", 1) - 1, self.name


class PlanItem(_HilItem):
    """Passes when the plan ran to its end (PASS, or FAIL by a check); its checks are items of
    their own."""

    line = 1

    def __init__(self, *, profile=None, **kwargs):
        super().__init__(**kwargs)
        self.profile = profile

    def runtest(self) -> None:
        result = self.parent.result(self.profile)
        self.user_properties.append(("outcome", result.outcome.value))
        self.user_properties.append(("reason", result.reason))
        if result.outcome is Outcome.SKIPPED:       # its link cannot run on this machine
            pytest.skip(result.reason)
        # a step that FAILed (not a check): the board tripped and the plan ended there
        tripped = any(s.outcome is Outcome.FAIL and s.kind != "check" for s in result.steps)
        if tripped or result.outcome in (Outcome.ERROR, Outcome.TIMEOUT, Outcome.ABORTED):
            raise HilCheckFailure(f"{result.source}: plan '{result.plan_name}' ended "
                                  f"{result.outcome.value}: {result.reason}")


class CheckItem(_HilItem):
    def __init__(self, *, check_name: str, line: int, profile=None, **kwargs):
        super().__init__(**kwargs)
        self.check_name = check_name
        self.line = line
        self.profile = profile

    def runtest(self) -> None:
        result = self.parent.result(self.profile)
        if result.outcome is Outcome.SKIPPED:
            pytest.skip(result.reason)
        check = _find(result, self.check_name)
        if check is None:
            raise HilCheckFailure(f"{result.source}:{self.line}: check '{self.check_name}' has no "
                                  f"result; the plan ended {result.outcome.value}: {result.reason}")
        self.user_properties.append(("outcome", check.outcome.value))
        if check.measured is not None:
            self.user_properties.append(("measured", f"{check.measured:.6g} {check.unit}"))
        if check.limits is not None:
            self.user_properties.append(("limits", check.limits.describe()))
        if check.outcome is Outcome.PASS:
            return
        if check.outcome is Outcome.INFO:
            # a finding: recorded with its value, never a failure (hil.plans roles)
            self.user_properties.append(("finding", check.message))
            return
        if check.outcome is Outcome.MARGINAL:
            warnings.warn(HilMarginalWarning(f"{self.check_name}: {check.message}"))
            return
        raise HilCheckFailure(f"{result.source}:{self.line}: check '{self.check_name}' "
                              f"{check.outcome.value}: {check.message}")


def _find(result: PlanResult, name: str) -> CheckResult | None:
    for c in result.checks:
        if c.name == name:
            return c
    return None


@pytest.fixture
def bench(request: pytest.FixtureRequest, tmp_path: Path):
    """A started bench (hil.run.runner.Bench) on --hil-link / --hil-mode, closed after the test.

    Its MCAP log is tmp_path/bench.mcap. Mark a test with
    ``@pytest.mark.hil_profile("path/to/profile.yaml")`` (or a profile name) to
    use another bench profile.
    """
    from hil.plans.format import PROFILE_NAMES
    from hil.run.runner import Bench

    kwargs: dict[str, Any] = {"log_path": tmp_path / "bench.mcap"}
    for key in ("link", "mode"):
        value = request.config.getoption(f"--hil-{key}")
        if value is not None:
            kwargs[key] = value
    marker = request.node.get_closest_marker("hil_profile")
    if marker is not None and marker.args[0] not in PROFILE_NAMES:
        from hil.session.board_params import load_bench_profile

        kwargs["profile"] = load_bench_profile(marker.args[0])
    with Bench(**kwargs) as b:
        yield b


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "hil_profile(name_or_path): bench profile for the bench fixture")
