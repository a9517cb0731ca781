"""Runs plans: steps in simulated time against a session, then checks, then reports.

A plan's steps execute in order on one BenchSession. Stimuli and commands act
at the current period; ``run``, ``wait_until`` and ``wait_ready`` advance periods
(a wait's timeout is enforced to the period, in simulated time); ``mark`` names the
current time; a ``check`` remembers when it was reached and is evaluated at the
end over the recorded signals (its window may reach back to any mark).

Whatever ends the run — its last step, a TIMEOUT, a dead board (ERROR), Ctrl-C
(ABORTED) — the session's teardown safe-states the plant and closes the log,
and the reports (JUnit XML, HTML, JSON record) are written with every check,
the ones never reached marked SKIPPED.
"""
from __future__ import annotations

import datetime as _dt
import functools
import math
import sys
import time
from dataclasses import field
from pathlib import Path
from typing import Any, Callable, Iterable

from plant_rt import TRUTH_FIELDS
from hil.session.board_params import load_bench_profile

from hil.plans.checks import evaluate_check
from hil.plans.outcome import CheckResult, Outcome, PlanResult, StepResult, plan_outcome
from hil.plans.format import (
    PROFILE_NAMES, CheckStep, ProfileRef, resolve_profile, CommandStep, DcLinkStep, FaultStep, LoadStep, MarkStep, ParamSetStep,
    Plan, PlantParamStep, RunStep, WaitReadyStep, WaitUntilStep, bind_plan, check_control_inputs, load_plan,
    plan_files,
)
from hil.logs.recorder import SENSOR_FIELDS, TELEMETRY_FIELDS, COMMAND_FIELDS
from hil.reports.html import slug, write_reports, write_summary
from hil.session.bench_session import BenchSession, SessionConfig, SessionError
from hil.links.registry import LinkUnavailable
from hil.session.bench_session import _fault_text as fault_text    # SPEC 2.9's wording
from hil.session.board_state import fault_name
from hil.control_inputs import ControlLimits
from hil.plans.signals import SENSOR_SET_SIGNALS, SignalSet
from configfile.dataclass_methods import dataclass
from configfile.source import ConfigError

PROGRESS_CHUNK_S = 0.01  # simulated seconds between progress updates and wall-clock checks


class PlanTimeout(Exception):
    """A step's own time limit, or the plan's wall-clock budget, ran out."""


class BoardTripped(Exception):
    """The board tripped (a FAULT, a shoot-through) where the plan did not provoke it: the step
    ends at once and the plan ends FAIL, naming the cause (a verdict on the board)."""


class TripWatch:
    """Board FAULTs and shoot-throughs since the plan began, against what the plan expects.

    A run in which a fault has been injected (a plan's `fault` step, the Modbus fault bits, the
    Python API: hil/faults/injector.py) or whose plan says `expect_fault: true` expects the
    board may trip: its checks judge the trip (ctrl.fault_code, ctrl.state). Any other run
    ends at the first trip; the step running then ends at once."""

    def __init__(self, session: BenchSession, expected: bool = False):
        self.session = session
        self.expected = expected
        self._faults = len(session.faults)
        self._shoot_throughs = session.shoot_throughs

    def __call__(self) -> bool:
        """True when the board has tripped and the run does not expect it (every period: the
        counts first, the injector's history only after a trip)."""
        s = self.session
        if len(s.faults) == self._faults and s.shoot_throughs == self._shoot_throughs:
            return False
        return not self._expected_now()

    def _expected_now(self) -> bool:
        injector = self.session.fault_injector
        if not self.expected and injector is not None:
            self.expected = any(r["action"] == "inject" for r in injector.history)
        return self.expected

    def cause(self) -> str:
        """The first trip in words: 'period 14 (t = 0.0007 s): board FAULT 1 OVERCURRENT,
        value 20.09 A' (SPEC 2.9's wording, as the session's warning)."""
        s = self.session
        if len(s.faults) > self._faults:
            return fault_text(s.faults[self._faults], s.period_s)
        shoot = next((data for _t, kind, data in s.events if kind == "shoot_through"), None)
        if shoot is None:
            return "shoot-through"
        k = shoot["period"]
        return (f"period {k} (t = {k * s.period_s:.6g} s): shoot-through, GATES "
                f"0x{shoot['gates']:02x} turns on both switches of leg {', '.join(shoot['legs'])}")

    def check(self, where: str) -> None:
        if self():
            raise BoardTripped(f"{where}: the board tripped: {self.cause()}")


def expand_plan_paths(paths: Iterable[str | Path]) -> list[Path]:
    files = plan_files(paths)
    missing = [p for p in files if not p.exists()]
    if missing:
        raise ConfigError("no such plan file or directory", str(missing[0]))
    return files


def profile_ref(plan: Plan, profile: "str | Path | ProfileRef | None" = None) -> ProfileRef:
    """The profile a run uses: the given one (a ProfileRef, a name, or a path relative to the
    working directory), else the plan's first (`profile:` / `profiles:`; default paper)."""
    if isinstance(profile, ProfileRef):
        return profile
    if profile is not None:
        try:
            return resolve_profile(str(profile), Path.cwd())
        except ValueError as exc:
            raise ConfigError(str(exc), str(plan.source_path)) from None
    if plan.profiles:
        return plan.profiles[0]
    if plan.profile_path is not None:
        return ProfileRef(plan.profile or str(plan.profile_path), plan.profile_path)
    if plan.profile not in (None, *PROFILE_NAMES):
        raise ConfigError(f"unknown profile '{plan.profile}' (named profiles: "
                          f"{', '.join(PROFILE_NAMES)}, or a path to a YAML file)",
                          str(plan.source_path))
    return ProfileRef(plan.profile or "paper", None)


def board_for(plan: Plan, link: str | None = None, board=None):
    """The board file of a run: the given one (a BoardFile or a path), else the plan's
    `board:`, else the link's default (hil.session.board_params.default_board)."""
    from hil.boards import BoardFile, load_board
    from hil.session.board_params import default_board

    if isinstance(board, BoardFile):
        return board
    if board is not None:
        return load_board(board)
    if plan.board_path is not None:
        return load_board(plan.board_path)
    return default_board(link or plan.link or "stub")


def check_plan_board(plan: Plan, board, profile=None) -> None:
    """Every `param_set` of the plan names a parameter the board takes, with a value in its
    range, and every sensor-set signal it names (``sample.hall``) is one the board's
    `sensors:` carries: ConfigError naming the plan's file, line and key, before anything runs.
    `profile`: the run's bench profile (its thermal model logs the winding temperature)."""
    for step in plan.steps:
        if not isinstance(step, ParamSetStep):
            continue
        for name, value in step.params:
            problem = board.check_value(name, value)
            if problem is not None:
                raise ConfigError(problem, str(plan.source_path), step.line,
                                  f"steps[{step.index}].param_set.{name}")
    recorded = sensor_set_signals(board, profile)
    for line, key, name in _signal_uses(plan):
        if name in SENSOR_SET_SIGNALS and name not in recorded:
            raise ConfigError(_unrecorded_why(name, board), str(plan.source_path), line, key)


def sensor_set_signals(board, profile=None) -> set[str]:
    """The sensor-set signals (hil.plans.signals.SENSOR_SET_SIGNALS) a run on `board` records:
    ``sample.<field>`` of each field of its `sensors:`, and the winding temperature on a
    board with a sensor set or a profile whose thermal model is on."""
    from hil.boards.sensor_fields import WINDING_TEMPERATURE_SIGNAL, fields_of_set

    mask = board.sensor_set
    out = {f"sample.{f}" for f in fields_of_set(mask)}
    if mask or (profile is not None and profile.thermal.enabled):
        out.add(WINDING_TEMPERATURE_SIGNAL)
    return out


def _unrecorded_why(name: str, board) -> str:
    from hil.boards.sensor_fields import sensor_of_signal

    sensor = sensor_of_signal(name)
    has = f"its sensors: [{', '.join(board.sensors)}]" if board.sensors else \
        "it has no sensors: list (today's SAMPLE)"
    if sensor is None:
        return (f"signal '{name}' is recorded only on a board with a sensor set or a profile "
                f"whose thermal model is on (thermal.enabled); board '{board.name}' "
                f"({board.source}): {has}")
    return (f"signal '{name}' needs sensor '{sensor}' in the board's sensor set; board "
            f"'{board.name}' ({board.source}): {has}")


def _signal_uses(plan: Plan):
    """(line, key, signal) of every signal the plan names: waits, checks, plots."""
    for step in plan.steps:
        if isinstance(step, WaitUntilStep):
            yield step.line, f"steps[{step.index}].wait_until.signal", step.signal
        elif isinstance(step, CheckStep):
            for role, value in step.roles.items():
                if isinstance(value, str):
                    yield step.line, f"steps[{step.index}].check.{role}", value
    for j, spec in enumerate(plan.plots):
        for name in spec.signals:
            yield spec.line, f"plots[{j}]", name


def plan_runs(plans: Iterable[Plan], profile=None) -> list[tuple[Plan, ProfileRef]]:
    """Every (plan, profile) a command runs: each plan on `profile` when given, else on each
    of its own profiles."""
    return [(plan, ref) for plan in plans
            for ref in ([profile_ref(plan, str(profile))] if profile else
                        (plan.profiles or [profile_ref(plan)]))]


def validate_run(plan: Plan, ref: ProfileRef, link: str | None = None, board=None) -> None:
    """What a run of `plan` on `ref` needs, checked without running anything: the profile
    loads with the plan's overrides, the board takes every param_set, the commands and loads
    lie within the profile's ranges. ConfigError naming the file, line and key."""
    try:
        profile = profile_for(plan, ref)
    except ConfigError as exc:
        if exc.source == str(plan.source_path):
            raise
        # the profile's own file, line and key, and the plan that runs on it
        raise ConfigError(f"{exc.message} (profile '{ref.label}' of plan "
                          f"{plan.source_path})", exc.source, exc.line, exc.key) from None
    board_file = board_for(plan, link, board)
    # formulas (limits, stimuli) evaluated for this profile and board, as the run will
    plan = bind_plan(plan, profile, board_file, ref.label)
    check_plan_board(plan, board_file, profile)
    check_control_inputs(plan.steps, ControlLimits.from_profile(profile), str(plan.source_path))


def validate_runs(runs: Iterable[tuple[Plan, ProfileRef]], link: str | None = None,
                  board=None) -> None:
    """validate_run for every run, and each link string once (hil.links.registry.check_link),
    before the first run: a typo is one error, not one per plan."""
    from hil.links.registry import check_link

    runs = list(runs)
    for spec in dict.fromkeys(link or plan.link or "stub" for plan, _ref in runs):
        check_link(spec)
    for plan, ref in runs:
        validate_run(plan, ref, link, board)


def profile_for(plan: Plan, profile: "str | Path | ProfileRef | None" = None):
    """The bench profile of a run (profile_ref), with the plan's overrides applied."""
    ref = profile_ref(plan, profile)
    return load_bench_profile(ref.path, overrides=dict(plan.overrides) or None)


def plan_dir_name(plan: Plan, ref: ProfileRef | None = None) -> str:
    """out/<plan>/ for a plan run on its one profile; out/<plan>/<profile>/ when the plan lists
    several (or runs on one it does not list), so each profile's reports sit side by side."""
    labels = [r.label for r in plan.profiles] or ["paper"]
    if ref is None or (len(labels) == 1 and ref.label == labels[0]):
        return slug(plan.name)
    return f"{slug(plan.name)}/{profile_dir_name(ref)}"


def profile_dir_name(ref: ProfileRef) -> str:
    """A profile's folder: its name, or a profile file's stem ('../profiles/x.yaml' -> 'x'),
    never hidden from `ls` and globs by a leading dot."""
    label = ref.label
    if "/" in label or label.endswith((".yaml", ".yml")):
        label = Path(label).stem
    return slug(label).lstrip(".") or "profile"


# --------------------------------------------------------------------------- live signals
def live_getter(session: BenchSession, name: str) -> Callable[[], float]:
    """The latest value of a signal while running (wait_until), in its recorded unit."""
    group, _, fld = name.partition(".")
    rec = session.recorder
    if group == "plant" and fld in TRUTH_FIELDS:
        i = TRUTH_FIELDS.index(fld)
        return lambda: rec.latest("truth", i)
    if group == "sensor" and fld in SENSOR_FIELDS:
        i = SENSOR_FIELDS.index(fld)
        return lambda: rec.latest("sensors", i)
    if group == "ctrl" and fld in TELEMETRY_FIELDS:
        i = TELEMETRY_FIELDS.index(fld) + 1
        return lambda: rec.latest("telemetry", i)
    if group == "cmd" and fld in COMMAND_FIELDS:
        i = COMMAND_FIELDS.index(fld) + 1
        return lambda: rec.command_rows[-1][i] if rec.command_rows else math.nan
    if name in SENSOR_SET_SIGNALS:    # a sensor-set board's sample.*, the winding temperature
        field = "winding_temperature_degc" if group == "plant" else fld
        return lambda: rec.latest_sample(field)
    if name in rec.step_rows:       # board.state, board.ready, ctrl.fault_code, ...: 0 until set
        rows = rec.step_rows[name]
        return lambda: rows[-1][1] if rows else 0.0
    raise ConfigError(f"signal '{name}' is not recorded live", None)


def live_unit(name: str) -> str:
    from hil.logs.recorder import unit_of
    from hil.plans.signals import catalog_unit

    return catalog_unit(name) or unit_of(name.partition(".")[2]) or "1"


# --------------------------------------------------------------------------- stimuli
class Stimuli:
    """Per-period stimuli applied between periods: DC-link ramps, and a repeated load table
    (which the plant's load model does not have), evaluated once per period and held."""

    def __init__(self, session: BenchSession):
        self.session = session
        self.ramps: list[tuple[float, float, float, float]] = []  # t0, t1, v0, v1
        self.load_step: LoadStep | None = None
        self.load_t0 = 0.0
        self.load_before_nm = 0.0

    def per_period_load(self, step: LoadStep) -> None:
        plant = self.session.plant
        self.load_step, self.load_t0 = step, plant.t_s
        self.load_before_nm = plant.truth()[_LOAD_INDEX]
        self(plant.period)

    def dc_link(self, step: DcLinkStep) -> None:
        plant = self.session.plant
        if step.ramp_s <= 0:
            plant.set_dc_voltage(step.voltage_v)
            return
        now = plant.t_s
        v0 = plant.dc_source_voltage_v if hasattr(plant, "dc_source_voltage_v") else \
            self.session.profile.dc_link.source_voltage_v
        self.ramps = [(now, now + step.ramp_s, v0, step.voltage_v)]

    @property
    def idle(self) -> bool:
        """Nothing to apply this period: no ramp, no repeated load table (a period loop may
        then skip the call; only a plan step, between two run_periods, changes it)."""
        return not self.ramps and self.load_step is None

    def __call__(self, _period: int) -> None:
        if self.load_step is not None:
            plant = self.session.plant
            plant.load.set_constant(self.load_step.torque_at(plant.t_s - self.load_t0, 0.0,
                                                             self.load_before_nm))
        if not self.ramps:
            return
        t = self.session.plant.t_s
        t0, t1, v0, v1 = self.ramps[0]
        frac = min(max((t - t0) / (t1 - t0), 0.0), 1.0)
        self.session.plant.set_dc_voltage(v0 + frac * (v1 - v0))
        if frac >= 1.0:
            self.ramps.clear()


_LOAD_INDEX = TRUTH_FIELDS.index("load_torque_nm")


def apply_load(session: BenchSession, stimuli: Stimuli, step: LoadStep) -> None:
    load = session.plant.load
    now = session.plant.t_s
    stimuli.load_step = None
    # The plant's load is profile(t) + kw * speed: a step replaces both terms.
    load.set_speed_proportional(0.0)
    if step.type == "table" and step.repeat:
        stimuli.per_period_load(step)
    elif step.type == "constant":
        load.set_constant(step.torque_nm)
    elif step.type == "step":
        load.set_step(now + step.delay_s, step.torque_nm)
    elif step.type == "ramp":
        load.set_ramp(step.torque_nm, step.duration_s)
    elif step.type == "table":
        load.set_table([(now + t, nm) for t, nm in step.points])
    elif step.type == "speed_proportional":
        load.set_constant(step.offset_nm)
        load.set_speed_proportional(step.nm_per_rad_s)


# --------------------------------------------------------------------------- running
@dataclass
class RunOptions:
    """How run_plan runs a plan (run_plan's keyword arguments)."""

    link: str | None = None
    mode: str | None = None
    out_dir: Path | None = None
    seed: int = 0
    progress: Any = None            # callable(done_s, total_s) or None
    modbus: tuple[str, int] | None = None
    log: bool = True
    log_compression: str = "lz4"    # the MCAP log's chunks: lz4, zstd or none (SessionConfig)
    reports: bool = True            # False: only the MCAP log goes into out_dir (hil sweep)
    profile: Any = None             # a name, a path or a ProfileRef; None: the plan's first
    board: Any = None               # a BoardFile or a path; None: the plan's, else the link's
    live: Any = None                # hil.live.LiveStream: the run's channels to live viewers
    console: Any = None             # hil.run.console.EventConsole (any fn(t_s, kind, data))
    on_step: Any = None             # callable(step) as each step starts (the progress line)


@dataclass
class _RunState:
    """What a run has done so far: step results, checks reached and marks."""

    steps: list[StepResult] = field(default_factory=list)
    checks_reached: list[tuple[CheckStep, float]] = field(default_factory=list)
    marks: dict[str, float] = field(default_factory=lambda: {"start": 0.0})


def run_plan(plan: Plan, link: str | None = None, mode: str | None = None,
             out_dir: Path | None = None, seed: int = 0, progress=None,
             modbus: tuple[str, int] | None = None,
             reports: bool = True, profile=None, live=None, console=None,
             on_step=None, log_compression: str = "lz4",
             board=None) -> tuple[PlanResult, SignalSet]:
    """Runs one plan on one profile (default: the plan's first); writes log and (unless
    reports=False) reports into out_dir/<plan_dir_name> when given. Never raises for a
    failing board or plan: the outcome says what happened."""
    opts = RunOptions(link=link, mode=mode, out_dir=out_dir, seed=seed, progress=progress,
                      modbus=modbus, reports=reports, profile=profile, live=live,
                      console=console, on_step=on_step, log_compression=log_compression,
                      board=board)
    return _run(plan, opts)


def _run(plan: Plan, opts: RunOptions) -> tuple[PlanResult, SignalSet]:
    link = opts.link or plan.link or "stub"
    mode = opts.mode or plan.mode or "lockstep"
    plan_dir = None
    log_path = None
    ref = profile_ref(plan, opts.profile)
    if opts.out_dir is not None:
        plan_dir = Path(opts.out_dir) / plan_dir_name(plan, ref)
        plan_dir.mkdir(parents=True, exist_ok=True)
        log_path = plan_dir / "log.mcap"
    started = _dt.datetime.now(_dt.timezone.utc)
    wall0 = time.monotonic()
    state = _RunState()
    error = aborted = timeout = skipped = tripped = None
    session = None
    port = None
    try:
        profile = profile_for(plan, ref)
        board = board_for(plan, link, opts.board)
        # the plan's formulas (limits, stimuli) evaluated with this run's profile and board
        plan = bind_plan(plan, profile, board, ref.label)
        check_plan_board(plan, board, profile)
        # the plan's commands and loads within this profile's ranges, before any period
        check_control_inputs(plan.steps, ControlLimits.from_profile(profile), str(plan.source_path))
        config = SessionConfig(link=link, mode=mode, log_path=log_path, seed=opts.seed,
                               log_compression=opts.log_compression, board=board,
                               profile_label=ref.label,
                               metadata={"plan": {"name": plan.name, "source": str(plan.source_path),
                                                  "profile": ref.label}})
        session = BenchSession(profile, config)
        if opts.console is not None:
            session.event_listeners.append(opts.console)
        stimuli = Stimuli(session)
        session.on_period = stimuli
        session.start()
        if opts.live is not None:
            session.recorder.live = opts.live.follow(session.period_s)
        if opts.modbus is not None:
            from hil.faults.injector import apply_fault_bits
            from hil.ports.modbus import ControlMailbox, ModbusPort

            mailbox = ControlMailbox(load_torque_nm=profile.load.torque_nm,
                                     dc_link_voltage_v=profile.dc_link.source_voltage_v)
            session.attach_mailbox(mailbox, on_fault_bits=lambda bits: apply_fault_bits(session, bits))
            port = ModbusPort(mailbox, host=opts.modbus[0], port=opts.modbus[1],
                              isolation="process" if mode == "realtime" else "thread",
                              limits=ControlLimits.from_profile(profile))
            port.start()
        deadline = None if plan.timeout_s is None else wall0 + plan.timeout_s
        _execute(plan, session, stimuli, state, deadline, opts.progress, opts.on_step)
        session.drain()
    except KeyboardInterrupt:
        aborted = "aborted by the user (Ctrl-C)"
    except PlanTimeout as exc:
        timeout = str(exc)
    except LinkUnavailable as exc:      # e.g. no qemu-system-arm here: SKIPPED, with the reason
        skipped = str(exc)
    except BoardTripped as exc:
        tripped = str(exc)
    except (SessionError, ConfigError, OSError, ValueError, RuntimeError) as exc:
        error = str(exc)
    finally:
        if port is not None:
            port.stop()
        if session is not None:
            session.close(reason=aborted or skipped or error or timeout or tripped)
    sim_end = session.plant.t_s if session is not None else 0.0
    signals = SignalSet.from_arrays(session.recorder.arrays()) if session is not None else SignalSet()
    checks: list[CheckResult] = []
    by_name: dict[str, CheckResult] = {}
    for spec, now_s in state.checks_reached:
        result = evaluate_check(spec, signals, state.marks, now_s=now_s, results=by_name,
                                profile=ref.label)
        checks.append(result)
        by_name[spec.name] = result
    # A check step's outcome is its check's.
    steps = []
    for s in state.steps:
        match = next((c for c in checks if c.line == s.line and s.kind == "check"), None)
        if match is not None:
            outcome = {Outcome.PASS: Outcome.PASS, Outcome.MARGINAL: Outcome.PASS,
                       Outcome.INFO: Outcome.PASS,
                       Outcome.FAIL: Outcome.FAIL}.get(match.outcome, Outcome.ERROR)
            s = StepResult(s.index, s.kind, outcome, s.line, s.start_s, s.end_s, match.message)
        steps.append(s)
    why = aborted or skipped or error or timeout or tripped
    if why is not None:
        rest_steps, rest_checks = skipped_remainder(plan, steps, checks, why)
        steps += rest_steps
        checks += rest_checks
    outcome, reason = plan_outcome(steps, checks, error=error, aborted=aborted, timeout=timeout,
                                   skipped=skipped, tripped=tripped)
    extra: dict[str, Any] = {}
    if plan.constants:
        extra["constants"] = {name: d.to_json() for name, d in plan.constants.items()}
    if session is not None:
        extra["board"] = session.board_name
        extra["board_file"] = session.board.summary()
        extra["link_counters"] = session.link_counters() if session.conn is not None else {}
        extra["board_faults"] = [{"code": f.code, "name": fault_name(f.code), "period": f.period,
                                  "t_s": f.period * session.period_s, "value": f.value,
                                  "text": fault_text(f, session.period_s)}
                                 for f in session.faults]
        # every change of the board's STATUS state; "ready": true marks when it became ready
        extra["board_states"] = list(session.board_state.changes)
        if session.fault_injector is not None:
            extra["faults_injected"] = list(session.fault_injector.history)
        if session.rt_stats:
            extra["realtime"] = dict(session.rt_stats)
    result = PlanResult(
        plan_name=plan.name, source=str(plan.source_path), outcome=outcome, reason=reason,
        steps=tuple(steps), checks=tuple(checks), started_at=started.isoformat(timespec="seconds"),
        ended_at=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        sim_duration_s=sim_end, wall_duration_s=time.monotonic() - wall0, link=link, mode=mode,
        log_path=str(log_path) if log_path is not None else None, description=plan.description,
        marks=dict(state.marks), extra=extra, profile=ref.label)
    if plan_dir is not None and opts.reports:
        write_reports(result, signals, plan_dir, plan=plan)
    return result, signals


def _execute(plan: Plan, session: BenchSession, stimuli: Stimuli, state: _RunState,
             deadline: float | None, progress, on_step=None) -> None:
    period = session.period_s
    total_s = plan.min_sim_duration_s()
    chunk = max(1, round(PROGRESS_CHUNK_S / period))
    trips = TripWatch(session, expected=plan.expect_fault)

    def advance(count: int, stop=None) -> int:
        """Runs up to `count` periods; stops at once when the board trips (TripWatch)."""
        def stop_or_trip() -> bool:
            return trips() or (stop is not None and stop())

        done = 0
        while done < count:
            n = min(chunk, count - done)
            ran = session.run_periods(n, stop_or_trip)
            done += ran
            if progress is not None:
                progress(session.plant.t_s, total_s)
            if trips():
                break
            if deadline is not None and time.monotonic() > deadline:
                raise PlanTimeout(f"plan '{plan.name}' exceeded its wall-clock budget "
                                  f"timeout_s = {plan.timeout_s:g} s")
            if ran < n:
                break
        return done

    for step in plan.steps:
        if on_step is not None:
            on_step(step)
        t_start = session.plant.t_s
        where = f"step {step.index + 1} ({step.kind}, line {step.line})"
        try:
            outcome, message = _execute_step(step, session, stimuli, state, advance, t_start,
                                             trips)
            trips.check(where)
        except BoardTripped as exc:
            message = str(exc).removeprefix(f"{where}: ")
            state.steps.append(StepResult(step.index, step.kind, Outcome.FAIL, step.line, t_start,
                                          session.plant.t_s, message))
            raise
        except SessionError as exc:       # a watchdog trip, a failed link, a refusal: ERROR
            if not state.steps or state.steps[-1].index != step.index:
                state.steps.append(StepResult(step.index, step.kind, Outcome.ERROR, step.line,
                                              t_start, session.plant.t_s, str(exc)))
            raise
        state.steps.append(StepResult(step.index, step.kind, outcome, step.line, t_start,
                                      session.plant.t_s, message))


def _execute_step(step, session: BenchSession, stimuli: Stimuli, state: _RunState, advance,
                  t_start: float, trips: TripWatch) -> tuple[Outcome, str]:
    """One step; returns its outcome and message (a TIMEOUT records itself and raises)."""
    period = session.period_s
    outcome, message = Outcome.PASS, ""
    if isinstance(step, CommandStep):
        session.send_command(**step.changes())
    elif isinstance(step, ParamSetStep):
        for name, value in step.params:
            session.param_set(name, value)
    elif isinstance(step, LoadStep):
        apply_load(session, stimuli, step)
        session.event("load", type=step.type, torque_nm=step.torque_nm)
    elif isinstance(step, DcLinkStep):
        stimuli.dc_link(step)
        session.event("dc_link", voltage_v=step.voltage_v, ramp_s=step.ramp_s)
    elif isinstance(step, PlantParamStep):
        for name, value in step.params:
            session.plant.set_motor_param(name, value)
        session.event("plant_param", **dict(step.params))
    elif isinstance(step, FaultStep):
        from hil.faults.injector import apply_fault

        apply_fault(session, step)
    elif isinstance(step, RunStep):
        advance(round(step.duration_s / period))
    elif isinstance(step, WaitUntilStep):
        getter = live_getter(session, step.signal)
        test = step.predicate(live_unit(step.signal))
        hold_periods = max(1, round(step.hold_s / period)) if step.hold_s else 1
        held = [0]

        def met() -> bool:
            if test(getter()):
                held[0] += 1
            else:
                held[0] = 0
            return held[0] >= hold_periods

        limit = round(step.timeout_s / period)
        ran = advance(limit, met)
        if held[0] < hold_periods:
            trips.check(f"step {step.index + 1} (wait_until, line {step.line})")
            message = f"condition not met within {step.timeout_s:g} s: {step.describe()}"
            state.steps.append(StepResult(step.index, step.kind, Outcome.TIMEOUT, step.line,
                                          t_start, session.plant.t_s, message))
            raise PlanTimeout(f"step {step.index + 1} (wait_until, line {step.line}): {message}")
        message = f"met after {ran * period * 1e3:.1f} ms"
    elif isinstance(step, WaitReadyStep):
        message = _wait_ready(step, session, state, advance, t_start, trips)
    elif isinstance(step, MarkStep):
        state.marks[step.name] = session.plant.t_s
        session.event("mark", name=step.name)
    elif isinstance(step, CheckStep):
        # The last recorded sample is the previous period's (signals sit at t_k).
        state.checks_reached.append((step, max(session.plant.t_s - period, 0.0)))
    return outcome, message


def _wait_ready(step: WaitReadyStep, session: BenchSession, state: _RunState, advance,
                t_start: float, trips: TripWatch) -> str:
    """Runs until the board's STATUS says it is ready (hil/session/board_state.py); marks that
    moment. TIMEOUT names the state the board is in; a FAULT ends the step at once (FAIL, as
    any trip: BoardTripped)."""
    board = session.board_state
    period = session.period_s

    def done() -> bool:
        return board.ready or board.faulted

    if not done():
        advance(round(step.timeout_s / period), done)
    where = f"step {step.index + 1} (wait_ready, line {step.line})"
    if board.ready:
        t_ready = board.ready_t_s
        state.marks[step.mark] = t_ready
        session.event("mark", name=step.mark, at_s=t_ready, period=board.ready_period)
        return (f"board ready at t = {t_ready:.6f} s (period {board.ready_period}), "
                f"{max(t_ready - t_start, 0.0) * 1e3:.1f} ms after the wait began; mark '{step.mark}'")
    if board.faulted:
        fault = next((f for f in reversed(session.faults) if f.code == board.fault_code), None)
        what = (fault_text(fault, period) if fault is not None else
                f"board FAULT {board.fault_code} {fault_name(board.fault_code)} (STATUS)")
        raise BoardTripped(f"{where}: the board tripped before it was ready: {what}; its state "
                           f"is {board.describe()}")
    trips.check(where)        # a FAULT message ahead of the STATUS that says FAULT
    message = f"board not ready within {step.timeout_s:g} s: its state is {board.describe()}"
    state.steps.append(StepResult(step.index, step.kind, Outcome.TIMEOUT, step.line, t_start,
                                  session.plant.t_s, message))
    raise PlanTimeout(f"{where}: {message}")


# --------------------------------------------------------------------------- pytest / Python API
class Bench:
    """A running session for acceptance tests written in Python (the pytest ``bench`` fixture).

    >>> with Bench(link="stub") as bench:
    ...     bench.command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
    ...     bench.run(0.2)
    ...     assert abs(bench.signals()["plant.speed_rpm"].values[-1] - 1500) < 30
    """

    def __init__(self, link: str = "stub", mode: str = "lockstep", profile=None,
                 log_path: Path | None = None, seed: int = 0):
        self.profile = profile or load_bench_profile()
        self.session = BenchSession(self.profile, SessionConfig(link=link, mode=mode,
                                                                log_path=log_path, seed=seed))

    def __enter__(self) -> "Bench":
        self.session.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self.session.__exit__(*exc)

    @property
    def plant(self):
        return self.session.plant

    def command(self, **changes) -> None:
        self.session.send_command(**changes)

    def param_set(self, name: str, value: float) -> float:
        return self.session.param_set(name, value)

    def run(self, duration_s: float) -> None:
        self.session.run_periods(round(duration_s / self.session.period_s))

    @property
    def faults(self):
        """The fault injector: ``bench.faults.inject("open_phase", phase="a")`` (hil/faults/injector.py)."""
        from hil.faults.injector import injector

        return injector(self.session)

    def signals(self) -> SignalSet:
        return SignalSet.from_arrays(self.session.recorder.arrays())


# --------------------------------------------------------------------------- CLI
def _progress_bar(enabled: bool):
    """rich's progress line per plan: plan [profile], step, simulated time, rate against real
    time; None when disabled or stderr is not a terminal."""
    if not enabled or not sys.stderr.isatty():
        return None
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(TextColumn("{task.description}"), TextColumn("{task.fields[step]}"),
                    BarColumn(), TextColumn("{task.completed:.3f}/{task.total:.3f} s simulated"),
                    TextColumn("{task.fields[rate]}"), TimeElapsedColumn(),
                    console=Console(stderr=True), transient=True)


def _step_text(step, plan) -> str:
    where = f"line {step.line}" if getattr(step, "line", None) else ""
    return f"step {step.index + 1}/{len(plan.steps)} {step.kind} {where}".rstrip()


def run_command(args) -> int:
    files = expand_plan_paths(args.plans)
    if not files:
        print(f"hil run: no plans found in {', '.join(map(str, args.plans))}", file=sys.stderr)
        return 2
    plans = [load_plan(f) for f in files]  # validate every plan before anything runs
    board_arg = getattr(args, "board", None)
    wanted = getattr(args, "profile", None)
    runs = plan_runs(plans, wanted)
    # ... with its profile, its board and the link, each link string once
    validate_runs(runs, args.link, board_arg)
    modbus = None
    if args.modbus:
        from hil.cli.serve import parse_host_port

        modbus = parse_host_port(args.modbus)
    live = None
    if getattr(args, "live", None):
        from hil.live import LiveStream, parse_live_address

        live_host, live_port = parse_live_address(args.live)
        from hil.live.gate import FOXGLOVE_ORIGINS

        live = LiveStream(live_host, live_port, period_s=50e-6, mode=args.mode or "lockstep",
                          origins=FOXGLOVE_ORIGINS + tuple(getattr(args, "live_origin", None) or ()))
        print(f"hil run: live (Foxglove) on {live.url} (open in the app: {live.app_url})",
              file=sys.stderr)
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".hil-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise OSError(f"--out directory '{out}' is not writable: {exc.strerror}") from None
    entries = []
    bar = _progress_bar(not args.no_progress)
    from hil.run.console import EventConsole

    # Events go through the progress bar's console while it is drawn (lines do not tear).
    console = EventConsole(write=(lambda text: bar.console.print(text, markup=False, highlight=False))
                           if bar is not None else None)
    exit_code = 0
    try:
        if bar is not None:
            bar.start()
        for plan, ref in runs:
            on_step = None
            wall0 = time.monotonic()

            def callback(done, total, task=None):
                console.tick()
                if task is not None:
                    elapsed = max(time.monotonic() - wall0, 1e-9)
                    bar.update(task, completed=done, rate=f"{done / elapsed:.2f} x real time")
            if bar is not None:
                task = bar.add_task(f"{plan.name} [{ref.label}]", total=plan.min_sim_duration_s(),
                                    step="", rate="")
                callback = functools.partial(callback, task=task)
                on_step = lambda step, task=task, plan=plan: bar.update(task, step=_step_text(step, plan))
            console.prefix = f"hil: {plan.name} [{ref.label}]: "   # whose event it is
            result, _signals = run_plan(plan, link=args.link, mode=args.mode, out_dir=out,
                                        seed=args.seed, progress=callback, modbus=modbus,
                                        profile=ref, live=live, console=console, on_step=on_step,
                                        log_compression=args.log_compression,
                                        board=board_arg)
            console.close()
            if bar is not None:
                bar.remove_task(task)          # its verdict line below says how it ended
            if live is not None:              # connections refused, /cmd turned away
                for error in live.take_errors():
                    print(f"hil run: live: {error}", file=sys.stderr)
            plan_dir = out / plan_dir_name(plan, ref)
            entries.append((result, {"dir": plan_dir, "html": plan_dir / "report.html",
                                     "junit": plan_dir / "junit.xml", "json": plan_dir / "result.json",
                                     "log": plan_dir / "log.mcap"}))
            counts = result.counts()
            print(f"{result.outcome.value:8s} {plan.name} [{ref.label}]: {result.reason} "
                  f"[{counts.get('PASS', 0)} pass, {counts.get('MARGINAL', 0)} marginal, "
                  f"{counts.get('FAIL', 0)} fail, {counts.get('INFO', 0)} finding] ({result.sim_duration_s:.3f} s simulated in "
                  f"{result.wall_duration_s:.1f} s)")
            first = first_failing_check(result)
            if first is not None:
                print(f"         first failing check: {first}")
            if result.outcome is Outcome.ABORTED:
                exit_code = 2
                break
            if result.outcome is Outcome.ERROR:
                exit_code = 2
            elif result.outcome is Outcome.SKIPPED:
                pass                           # could not run here (its reason says why): exit 0
            elif not result.outcome.passed and exit_code == 0:
                exit_code = 1
    finally:
        if bar is not None:
            bar.stop()
        if live is not None:
            live.close()
        if entries:
            write_summary(entries, out)
            print(f"reports: {out / 'index.html'} (JUnit: {out / 'junit.xml'})")
    return exit_code


def first_failing_check(result: PlanResult) -> str | None:
    """The plan's first FAIL or ERROR check in words: its name, line, measured value and
    limits ('overshoot' (line 70): measured 7.2 %, limits <= 5 %); None if there is none."""
    c = next((c for c in result.checks if c.outcome in (Outcome.FAIL, Outcome.ERROR)), None)
    if c is None:
        return None
    where = f" (line {c.line})" if c.line is not None else ""
    unit = "" if c.unit in ("", "1") else f" {c.unit}"
    measured = "not computed" if c.measured is None else f"measured {c.measured:.6g}{unit}"
    limits = c.limits.describe() if c.limits is not None else "none"
    text = f"'{c.name}'{where} {c.outcome.value}: {measured}, limits {limits}"
    return text if c.measured is not None else f"{text}: {c.message}"


def skipped_remainder(plan: Plan, done_steps: list[StepResult],
                      done_checks: list[CheckResult], why: str) -> tuple[list[StepResult], list[CheckResult]]:
    """Steps and checks a plan never reached (it ended early), as SKIPPED results.

    The reports still list every check of the plan, so a CI system shows the
    checks that did not run instead of silently dropping them.
    """
    reached = {s.index for s in done_steps}
    checked = {c.name for c in done_checks}
    steps: list[StepResult] = []
    checks: list[CheckResult] = []
    for step in plan.steps:
        if step.index in reached:
            continue
        steps.append(StepResult(step.index, step.kind, Outcome.SKIPPED, step.line, message=why))
        if isinstance(step, CheckStep) and step.name not in checked:
            unit = step.limits.unit if step.limits is not None else ""
            checks.append(CheckResult(step.name, step.check_kind, Outcome.SKIPPED, None, unit,
                                      step.limits, f"not evaluated: {why}",
                                      signals=step.signals, line=step.line))
    return steps, checks
