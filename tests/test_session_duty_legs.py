"""A board that answers SAMPLE with DUTY_LEGS (SPEC 6.12), through the real serial link, codec
and session: the bench accepts the answer, floats the legs it names, and records the leg
enables. The reference is a plant of the same profile and seed stepped directly with the same
duties and leg enables: the session's recorded truth must equal it, period by period."""
from __future__ import annotations

import numpy as np
from plant_rt import Plant, load_profile
from protocol.messages import CAP_DUTY_LEGS, CAP_TELEMETRY, LEG_A, LEG_B, LEG_C, DutyLegs

from hil.session.bench_session import LEG_ENABLE_SIGNAL, BenchSession, SessionConfig
from hil.session.policy import SessionPolicy
from tests.fake_board import FakeBoard

FAST = SessionPolicy(hello_wait_s=0.5, param_wait_s=0.5, answer_wait_min_s=0.5, watchdog_s=5.0)
PERIODS = 48
COMMUTATION_PERIODS = 8
# Six-step from standstill: (duties 0..65535, leg enables): one leg PWM, one low, one floated.
STEPS = [((39321, 0, 0), LEG_A | LEG_B), ((39321, 0, 0), LEG_A | LEG_C),
         ((0, 39321, 0), LEG_B | LEG_C), ((0, 39321, 0), LEG_B | LEG_A),
         ((0, 0, 39321), LEG_C | LEG_A), ((0, 0, 39321), LEG_C | LEG_B)]


def command(k: int) -> tuple[tuple[int, int, int], int]:
    return STEPS[k // COMMUTATION_PERIODS % len(STEPS)]


def answer(sample, encoder) -> bytes:
    duty, legs = command(sample.period)
    if sample.period == 5:
        legs |= 0xF8                    # reserved bits: the bench must ignore them (SPEC 4)
    stale = b""
    if sample.period == 20:             # an answer for another period first: counted, not applied
        stale = encoder.encode(DutyLegs(19, (65535, 65535, 65535), LEG_A | LEG_B | LEG_C))
    return stale + encoder.encode(DutyLegs(sample.period, duty, legs))


def test_board_answering_duty_legs_floats_its_legs():
    with FakeBoard(capabilities=CAP_DUTY_LEGS | CAP_TELEMETRY, on_sample=answer) as board:
        config = SessionConfig(link=board.url, policy=FAST, hold_cpu_latency=False)
        with BenchSession(load_profile(), config) as session:
            session.run_periods(PERIODS)
            assert (session.missed_answers, session.stale_answers) == (0, 1)
            assert not [e for e in session.events if e[1] == "answer_type"]  # advertised
            truth = session.recorder.truth_rows
            signals = session.recorder.arrays()
    reference = Plant(load_profile(), seed=0)
    expected = []
    for k in range(PERIODS):
        expected.append(reference.truth())
        duty, legs = command(k)
        reference.step(duty=tuple(d / 65535.0 for d in duty), legs=legs)
    assert np.array_equal(truth, np.asarray(expected))
    # the floated phase of the first commutation step carries no current at standstill (i_c is
    # -(i_a + i_b): zero to rounding), while A drives amperes into B
    i_a, i_c = truth[1:COMMUTATION_PERIODS, 1], truth[1:COMMUTATION_PERIODS, 3]
    assert np.all(np.abs(i_c) < 1e-12) and np.all(i_a > 0.1)
    _, leg_enable, _ = signals[LEG_ENABLE_SIGNAL]
    assert list(leg_enable) == [command(k)[1] for k in range(PERIODS)]


def test_duty_legs_from_a_board_that_does_not_advertise_it_is_accepted_and_logged():
    """SPEC 2.8.4: a GATES-only board answering DUTY_LEGS is accepted and logged once."""
    with FakeBoard(capabilities=0x1, on_sample=answer) as board:
        config = SessionConfig(link=board.url, policy=FAST, hold_cpu_latency=False)
        with BenchSession(load_profile(), config) as session:
            session.run_periods(4)
            notes = [e[2] for e in session.events if e[1] == "answer_type"]
    assert notes == [{"type": "DUTY_LEGS", "capabilities": 1,
                      "note": "answers with a type it does not advertise"}]
