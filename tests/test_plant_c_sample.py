"""Plant.sample() and Plant.truth() in the C kernel (plant_rt/c/_plantnet.c) against the Python
reference, period by period and bit for bit.

Two plants from the same profile and seed take the same gate words, one with the kernel
(ckernel.EXTENSION, wrapped to count which calls C answered and which it handed back to
Python), one with the kernel off (plant_rt/plant.py and plant_rt/sensors.py, the reference).
Every period their SensorSample and truth record must be equal bit for bit (floats compared
by their hex form, so -0.0 and 0.0 differ) and every ADC channel's noise stream must stand
at the same place (`_i`, and `_buf` after each refill). The runs cover the noise buffers'
refills (9,000 periods against blocks of 4,096), the three phase pairs, overcurrent and
overvoltage status bits, both directions of rotation with the angle wrapping and the
revolution count going negative, and every case the C code leaves to Python (sensor faults,
open phase, locked load, no current). One run perturbs the flux linkage handed to the C calls
by 1e-12 relative: the comparison must then report a difference, so it is shown that it can.
Physics tests (test_plant_sensors.py, test_plant_physics.py...) hold the Python code, the
reference, to the physics; this file holds the C code to the Python code.
"""
from __future__ import annotations

import math
import random

import pytest

from plant_rt import Plant, SensorSample, ckernel, load_profile
from plant_rt.sensors import STATUS_INDEX_PULSE, STATUS_OVERCURRENT, STATUS_OVERVOLTAGE

RATED_RAD_S = 3000.0 * 2.0 * math.pi / 60.0
WORDS = (0x29, 0x25, 0x26, 0x16, 0x1A, 0x19, 0x2A, 0x15)

needs_kernel = pytest.mark.skipif(ckernel.EXTENSION is None,
                                  reason=f"C kernel not built: {ckernel.UNAVAILABLE_REASON}")


class Counting:
    """The extension with its sample/truth answers counted (None: handed back to Python);
    `perturb` scales the flux linkage psi_alpha in their arguments (a broken input)."""

    def __init__(self, perturb: float = 0.0):
        self.answered = {"sample": 0, "truth": 0}
        self.declined = {"sample": 0, "truth": 0}
        self.perturb = perturb

    def __getattr__(self, name):
        return getattr(ckernel.EXTENSION, name)

    def _count(self, name, result):
        (self.declined if result is None else self.answered)[name] += 1
        return result

    def sample(self, sensors, motor, sample_type, period, pa, *rest):
        pa = pa * (1.0 + self.perturb)
        return self._count("sample", ckernel.EXTENSION.sample(sensors, motor, sample_type,
                                                              period, pa, *rest))

    def truth(self, motor, load, period, T, pa, *rest):
        pa = pa * (1.0 + self.perturb)
        return self._count("truth", ckernel.EXTENSION.truth(motor, load, period, T, pa, *rest))


def bits(record) -> tuple:
    return tuple(v.hex() if type(v) is float else (type(v).__name__, v) for v in record)


def make(kernel, overrides: dict, setup=None) -> Plant:
    plant = Plant(load_profile(overrides=overrides), seed=0)
    plant.use_c_kernel(kernel)
    if setup is not None:
        setup(plant)
    return plant


class Run:
    """What a comparison saw: the first difference (None: none), and the coverage."""

    def __init__(self, kernel: Counting):
        self.kernel = kernel
        self.mismatch = None
        self.status = 0
        self.refills = 0
        self.revs = set()
        self.negative_angle = False
        self.zero_current = False


def compare(overrides: dict, n: int, seed: int = 1, setup=None, each=None,
            kernel: Counting | None = None, words=WORDS) -> Run:
    """n periods of random gate words from `words`; each(k, plant) runs on both plants
    before period k's sample (faults switched on and off, phase pairs changed...)."""
    kernel = kernel or Counting()
    c_plant = make(kernel, overrides, setup)
    py_plant = make(False, overrides, setup)
    assert c_plant._c_sample is not None and py_plant._c_sample is None
    run = Run(kernel)
    rng = random.Random(seed)
    channels = [(getattr(c_plant.sensors, name), getattr(py_plant.sensors, name))
                for name in ("i1", "i2", "vdc")]
    for k in range(n):
        if each is not None:
            each(k, c_plant)
            each(k, py_plant)
        run.zero_current |= py_plant._zero_current
        sc, sp = c_plant.sample(), py_plant.sample()
        tc, tp = c_plant.truth(), py_plant.truth()
        if type(sc) is not SensorSample or bits(sc) != bits(sp) or sc != sp:
            run.mismatch = (k, "sample", sc, sp)
            return run
        if type(tc) is not tuple or bits(tc) != bits(tp):
            run.mismatch = (k, "truth", tc, tp)
            return run
        assert c_plant.sample() is sc                   # once per period
        for c_ch, p_ch in channels:
            if c_ch._i != p_ch._i or len(c_ch._buf) != len(p_ch._buf):
                run.mismatch = (k, "noise index", c_ch._i, p_ch._i)
                return run
            if p_ch._i == 1:                            # just refilled
                run.refills += 1
                if c_ch._buf != p_ch._buf:
                    run.mismatch = (k, "noise buffer", None, None)
                    return run
        run.status |= sp.status
        run.revs.add(py_plant._revs)
        run.negative_angle |= py_plant._th < 0.0
        g = rng.choice(words)
        c_plant.step(g)
        py_plant.step(g)
    return run


@needs_kernel
@pytest.mark.parametrize("phases", ["ab", "ac", "bc"])
@pytest.mark.parametrize("speed", [RATED_RAD_S, -RATED_RAD_S])
def test_sample_and_truth_c_equal_python_bit_for_bit(phases, speed):
    """9,000 periods: noise refills, angle wraps both ways, overcurrent; overvoltage from
    period 4,000 (a surge above the 90 V trip), back at period 6,000."""
    def surge(k, plant):
        if k == 4000:
            plant.set_dc_voltage(95.0)
        elif k == 6000:
            plant.set_dc_voltage(70.0)

    run = compare({"sensors": {"current": {"phases": phases}},
                   "initial": {"speed_rad_s": speed}}, 9000, each=surge)
    assert run.mismatch is None, run.mismatch
    assert run.refills >= 6                 # 3 channels, 2 refills each after the first block
    assert run.status & STATUS_OVERCURRENT and run.status & STATUS_OVERVOLTAGE
    assert run.status & STATUS_INDEX_PULSE
    assert run.negative_angle and (min(run.revs) < 0 if speed < 0 else max(run.revs) > 0)
    assert len(run.revs) > 3
    # C answered all but the refill periods (every channel refills in the same period)
    assert run.kernel.declined["sample"] <= 3 and run.kernel.answered["sample"] > 8990
    assert run.kernel.declined["truth"] == 0


@needs_kernel
def test_phase_pair_changed_while_running():
    phases = ["ac", "bc", "ab"]

    def switch(k, plant):
        if k % 500 == 250:
            plant.sensors.phases = phases[(k // 500) % 3]

    run = compare({}, 3000, seed=2, each=switch)
    assert run.mismatch is None, run.mismatch


def _faults_on_and_off(on, off=None):
    """each(): the fault from period 300 to 700, and from 1,200 to the end."""
    def each(k, plant):
        if k in (300, 1200):
            on(plant)
        elif k == 700:
            (off or (lambda p: None))(plant)
    return each


def _stuck(p):
    p.sensors.i1.stuck_counts = 100


def _unstuck(p):
    p.sensors.i1.stuck_counts = None


def _window(p):
    p.sensors.vdc.saturation = (10, 2800)


def _unwindow(p):
    p.sensors.vdc.saturation = None


def _extra_noise(p):
    p.sensors.i2.set_extra_noise(3.0, seed=5)


def _extra_noise_shared(p):
    p.sensors.i1.set_extra_noise(2.0)


def _enc_missing(p):
    p.sensors.encoder.set_missing_counts(0.1, seed=3)


def _enc_found(p):
    p.sensors.encoder.set_missing_counts(0)
    p.sensors.encoder.reset_lost_counts()          # lost counts stay lost until reset


def _enc_noise(p):
    p.sensors.encoder.set_noise(2.0, seed=4)


def _enc_invert(p):
    p.sensors.encoder.invert = True


def _enc_no_index(p):
    p.sensors.encoder.index_missing = True


def _enc_stuck(p):
    p.sensors.encoder.stuck_counts = 77


def _open_b(p):
    p.set_open_phase("b")


def _gains(p):
    p.sensors.i1.gain = 1.1
    p.sensors.i2.offset = 0.5
    p.sensors.encoder.offset_counts = 123
    p.sensors.i1.noise_rms_counts = 0


FAULTS = [
    ("adc stuck", _faults_on_and_off(_stuck, _unstuck), "sample"),
    ("adc window", _faults_on_and_off(_window, _unwindow), "sample"),
    ("extra noise, own stream", _faults_on_and_off(_extra_noise,
                                                   lambda p: p.sensors.i2.clear_extra_noise()),
     None),
    ("extra noise, channel's stream", _faults_on_and_off(_extra_noise_shared,
                                                         lambda p: p.sensors.i1.clear_extra_noise()),
     None),
    ("encoder missing counts", _faults_on_and_off(_enc_missing,
                                                  _enc_found),
     "sample"),
    ("encoder noise", _faults_on_and_off(_enc_noise, lambda p: p.sensors.encoder.set_noise(0)),
     "sample"),
    ("encoder inverted", _faults_on_and_off(_enc_invert,
                                            lambda p: setattr(p.sensors.encoder, "invert", False)),
     "sample"),
    ("index missing", _faults_on_and_off(_enc_no_index,
                                         lambda p: setattr(p.sensors.encoder, "index_missing",
                                                           False)), "sample"),
    ("encoder stuck", _faults_on_and_off(_enc_stuck,
                                         lambda p: setattr(p.sensors.encoder, "stuck_counts",
                                                           None)), "sample"),
    ("open phase", _faults_on_and_off(_open_b, lambda p: p.set_open_phase(None)), "plant"),
    ("gain, offset, no noise on i1", _faults_on_and_off(_gains), None),
]


@needs_kernel
@pytest.mark.parametrize("name,each,declines", FAULTS, ids=[f[0] for f in FAULTS])
def test_faults_run_the_python_code_and_the_streams_stay_in_step(name, each, declines):
    run = compare({"initial": {"speed_rad_s": 0.5 * RATED_RAD_S}}, 5000, seed=3, each=each)
    assert run.mismatch is None, (name, run.mismatch)
    kernel = run.kernel
    assert kernel.answered["sample"] > 500 and kernel.answered["truth"] > 500
    if declines == "sample":
        assert kernel.declined["sample"] > 4000
    elif declines == "plant":       # Plant.sample and Plant.truth do not call the kernel
        assert kernel.answered["sample"] < 1000 and kernel.answered["truth"] < 1000
    else:
        assert kernel.declined["sample"] <= 8           # the noise refills only
    assert kernel.declined["truth"] == 0


@needs_kernel
def test_locked_load_and_no_current_run_the_python_code():
    run = compare({"load": {"locked": True}}, 800, seed=4)
    assert run.mismatch is None, run.mismatch
    assert run.kernel.declined["truth"] == 800 and run.kernel.answered["truth"] == 0
    assert run.kernel.answered["sample"] > 790
    # coasting with every switch off from a low speed: the current dies out (_zero_current)
    run = compare({"initial": {"speed_rad_s": 20.0}}, 400, seed=4, words=(0,))
    assert run.mismatch is None, run.mismatch
    assert run.zero_current


@needs_kernel
def test_load_profile_pieces_c_equal_python():
    """A load table with a ramp, a step and a speed term: Load.torque in C, every piece."""
    def table(k, plant):
        if k == 10:
            t = plant.t_s
            plant.load.set_table([(t + 0.002, 0.0), (t + 0.01, 0.8), (t + 0.01, -0.3),
                                  (t + 0.02, 0.1)])
            plant.load.set_speed_proportional(1e-3)

    run = compare({}, 1500, seed=5, each=table)
    assert run.mismatch is None, run.mismatch
    assert run.kernel.answered["truth"] == 1500


@needs_kernel
def test_the_comparison_fails_when_the_c_side_gets_a_perturbed_flux():
    run = compare({}, 200, seed=6, kernel=Counting(perturb=1e-12))
    assert run.mismatch is not None and run.mismatch[0] == 0


@needs_kernel
def test_the_kernel_declines_without_changing_anything():
    ext = ckernel.EXTENSION
    plant = Plant(load_profile(), seed=0)
    plant.use_c_kernel(True)
    for g in WORDS * 10:
        plant.sample()
        plant.step(g)
    s = plant.sensors

    def args(**change):
        a = dict(sensors=s, motor=plant.motor, sample_type=SensorSample, period=plant.period,
                 pa=plant._pa, pb=plant._pb, th=plant._th, revs=plant._revs, vdc=plant._vdc,
                 flags=plant._flags)
        a.update(change)
        return tuple(a.values())

    before = [(ch._i, ch._buf) for ch in (s.i1, s.i2, s.vdc)]
    s.vdc._i = len(s.vdc._buf)                  # exhausted: Python refills it
    assert ext.sample(*args()) is None
    assert [(ch._i, ch._buf) for ch in (s.i1, s.i2)] == before[:2]
    s.vdc._i = before[2][0]
    for bad in (dict(pa=math.nan), dict(th=math.inf), dict(revs=2**40), dict(flags=1.0),
                dict(sensors=object())):
        assert ext.sample(*args(**bad)) is None, bad
    assert [(ch._i, ch._buf) for ch in (s.i1, s.i2, s.vdc)] == before
    base = type(plant.motor)

    class Motor(base):          # a subclass might override what Plant calls: Python runs
        __slots__ = ()

    plant.motor.__class__ = Motor
    assert ext.sample(*args()) is None
    assert ext.truth(plant.motor, plant.load, plant.period, plant._T, plant._pa, plant._pb,
                     plant._th, plant._w, plant._vdc, plant._idc_int, plant._u_int) is None
    plant.motor.__class__ = base
    sample = ext.sample(*args())
    assert sample == SensorSample(*sample) and s.i1._i == before[0][0] + 1
    with pytest.raises(TypeError):
        ext.sample(*args()[:9])
    with pytest.raises(TypeError):
        ext.sample(*args(sample_type=3))
    # where the Python code raises (int(nan), math.cos(inf)) C declines and it does
    c, py = Plant(load_profile(), seed=0), Plant(load_profile(), seed=0)
    py.use_c_kernel(False)
    for p in (c, py):
        p._th = math.inf
        with pytest.raises(ValueError):
            p.truth()
        with pytest.raises(ValueError):
            p.sample()
        p._th = math.nan
        with pytest.raises(ValueError):
            p.sample()
    assert bits(c.truth()) == bits(py.truth())          # NaNs, no exception
    c._th = py._th = 0.0
    c._pa = py._pa = math.nan
    assert bits(c.truth()) == bits(py.truth())
