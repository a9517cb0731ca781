"""Recorded signals: name -> (time, values, unit), one sample per control period.

Names follow the log: ``plant.<field>`` for the plant truth, ``sensor.<field>``
for what was sent to the board, ``ctrl.<field>`` for the board's TELEMETRY and
``cmd.<field>`` for what the bench commanded (a step signal). The catalogue
below is what plans are validated against; the runner may record more (e.g.
faults of issue 7 register their signals with `register_signal`).
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping

import numpy as np

from configfile.dataclass_methods import dataclass
from hil.plans.units import canonical, convert

_PLANT = {
    "t_s": "s", "i_a": "A", "i_b": "A", "i_c": "A", "i_alpha": "A", "i_beta": "A",
    "psi_alpha": "Wb", "psi_beta": "Wb", "flux_mag_wb": "Wb", "torque_nm": "Nm",
    "speed_rad_s": "rad/s", "speed_rpm": "rpm", "theta_e_rad": "rad", "theta_m_rad": "rad",
    "v_dc": "V", "i_dc": "A", "load_torque_nm": "Nm", "u_alpha": "V", "u_beta": "V",
}
_SENSOR = {"adc_i1": "count", "adc_i2": "count", "adc_vdc": "count", "encoder": "count",
           "status": "1"}
_CTRL = {
    "sector": "1", "speed_source": "1", "state": "1", "gates": "1",
    "speed_feedback_rad_s": "rad/s", "speed_encoder_rad_s": "rad/s", "speed_raw_rad_s": "rad/s",
    "speed_lpf_rad_s": "rad/s", "speed_ekf_rad_s": "rad/s", "flux_angle_rad": "rad",
    "ekf_angle_rad": "rad", "flux_mag_wb": "Wb", "torque_est_nm": "Nm", "torque_ref_nm": "Nm",
    "rotor_pos_conv_rad": "rad", "rotor_pos_ekf_rad": "rad",
}
_CMD = {"speed_ref_rpm": "rpm", "enable": "1", "speed_source": "1", "torque_mode": "1",
        "torque_ref_nm": "Nm", "flux_ref_wb": "Wb"}
# Step signals (hil/logs/recorder.py step_value): the board's latched fault code from FAULT and
# STATUS (0 before any), the Modbus bits of the injected faults in effect (hil/faults/injector.py),
# and the board's state from STATUS (SPEC 9.4) and its ready flag (hil/session/board_state.py),
# and the leg enables of a DUTY_LEGS board's answers (bit x = leg x switching; 0 before the first).
_STEP = {"ctrl.fault_code": "1", "fault.active_bits": "1", "board.state": "1", "board.ready": "1",
         "ctrl.leg_enable": "1"}

# What a sensor-set board was sent (SAMPLE_SENSORS, hil/boards/sensor_fields.py), and the
# plant's winding temperature logged beside it: recorded only on such a board (and the
# temperature also when the profile's thermal model is on), so plans name them apart from the
# catalogue every run records; hil.run.runner.check_plan_board refuses one a run will not have.
_SAMPLE = {"adc_ia": "count", "adc_ib": "count", "adc_ic": "count", "adc_vdc": "count",
           "encoder": "count", "hall": "1", "adc_va": "count", "adc_vb": "count",
           "adc_vc": "count", "bemf_comparators": "1", "adc_resolver_sin": "count",
           "adc_resolver_cos": "count", "adc_temperature": "count"}
SENSOR_SET_SIGNALS: dict[str, str] = {
    **{f"sample.{k}": v for k, v in _SAMPLE.items()},
    "plant.winding_temperature_degc": "degC",
}

#: Every signal a plan may name, with its unit. Angles are wrapped to (-pi, pi].
SIGNAL_CATALOG: dict[str, str] = {
    **{f"plant.{k}": v for k, v in _PLANT.items()},
    **{f"sensor.{k}": v for k, v in _SENSOR.items()},
    **{f"ctrl.{k}": v for k, v in _CTRL.items()},
    **{f"cmd.{k}": v for k, v in _CMD.items()},
    **_STEP,
}


def register_signal(name: str, unit: str) -> None:
    """Adds a signal to the catalogue (a runner or fault module that records more)."""
    if "." not in name:
        raise ValueError(f"signal names are '<group>.<field>', got '{name}'")
    SIGNAL_CATALOG[name] = canonical(unit)


def catalog_unit(name: str) -> str | None:
    return SIGNAL_CATALOG.get(name) or SENSOR_SET_SIGNALS.get(name)


class MissingSignalError(KeyError):
    """A signal a check needs was not recorded."""

    def __init__(self, name: str, available: Iterable[str]):
        self.name = name
        self.available = sorted(available)
        super().__init__(name)

    def __str__(self) -> str:
        groups = sorted({a.split(".", 1)[0] for a in self.available})
        return (f"signal '{self.name}' was not recorded in this run "
                f"(recorded groups: {', '.join(groups) or 'none'})")


@dataclass(frozen=True, eq=False)
class Signal:
    """One recorded signal; t_s strictly increasing (one sample per period)."""

    name: str
    t_s: np.ndarray
    values: np.ndarray
    unit: str

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, dtype=float)
        v = np.asarray(self.values, dtype=float)
        if t.ndim != 1 or v.shape != t.shape:
            raise ValueError(f"signal '{self.name}': t_s and values must be 1-D of equal length "
                             f"(got {t.shape} and {v.shape})")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "unit", canonical(self.unit))

    def __len__(self) -> int:
        return len(self.t_s)

    def window(self, t0: float, t1: float) -> "Signal":
        """Samples with t0 <= t <= t1 (a nanosecond of tolerance on each side for float times)."""
        eps = 1e-9
        i0 = int(np.searchsorted(self.t_s, t0 - eps, side="left"))
        i1 = int(np.searchsorted(self.t_s, t1 + eps, side="right"))
        return Signal(self.name, self.t_s[i0:i1], self.values[i0:i1], self.unit)

    def to_unit(self, unit: str) -> "Signal":
        if canonical(unit) == self.unit:
            return self
        return Signal(self.name, self.t_s, convert(self.values, self.unit, unit), unit)

    def at(self, t: float) -> float:
        """Sample-and-hold value at time t (the last sample at or before t)."""
        i = int(np.searchsorted(self.t_s, t + 1e-9, side="right")) - 1
        if i < 0:
            raise ValueError(f"signal '{self.name}' has no sample at or before t = {t:g} s")
        return float(self.values[i])

    def resampled(self, t_s: np.ndarray) -> np.ndarray:
        """Values on other sample times by linear interpolation (held at the ends)."""
        if len(self.t_s) == len(t_s) and np.array_equal(self.t_s, t_s):
            return self.values
        return np.interp(t_s, self.t_s, self.values)


class SignalSet(Mapping[str, Signal]):
    """name -> Signal; `get` raises MissingSignalError naming what was recorded."""

    def __init__(self, signals: Iterable[Signal] | Mapping[str, Signal] = ()):
        items = signals.values() if isinstance(signals, Mapping) else signals
        self._signals: dict[str, Signal] = {}
        for s in items:
            self.add(s)

    def add(self, signal: Signal) -> None:
        self._signals[signal.name] = signal

    def __getitem__(self, name: str) -> Signal:
        try:
            return self._signals[name]
        except KeyError:
            raise MissingSignalError(name, self._signals) from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._signals)

    def __len__(self) -> int:
        return len(self._signals)

    @property
    def end_s(self) -> float:
        """The last recorded time over all signals (0 when empty)."""
        ends = [float(s.t_s[-1]) for s in self._signals.values() if len(s)]
        return max(ends) if ends else 0.0

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, tuple[np.ndarray, np.ndarray, str]]) -> "SignalSet":
        """From name -> (t_s, values, unit) (what the runner's recorder exports).

        A unit left empty by the recorder is taken from the catalogue when the
        catalogue knows the signal, so counts and flags keep their meaning.
        """
        out = cls()
        for name, (t, v, unit) in arrays.items():
            if not unit and catalog_unit(name) is not None:
                unit = catalog_unit(name)
            out.add(Signal(name, t, v, unit or "1"))
        return out

    def save_npz(self, path) -> None:
        """All signals into one compressed .npz (units in a side array)."""
        data = {}
        for name, s in self._signals.items():
            data[f"{name}|t"] = s.t_s
            data[f"{name}|v"] = s.values
            data[f"{name}|u"] = np.array(s.unit)
        np.savez_compressed(path, **data)

    @classmethod
    def load_npz(cls, path) -> "SignalSet":
        out = cls()
        with np.load(path) as data:
            names = sorted({k.rsplit("|", 1)[0] for k in data.files})
            for name in names:
                out.add(Signal(name, data[f"{name}|t"], data[f"{name}|v"], str(data[f"{name}|u"])))
        return out


__all__ = ["Signal", "SignalSet", "SIGNAL_CATALOG", "SENSOR_SET_SIGNALS", "MissingSignalError", "register_signal",
           "catalog_unit"]
