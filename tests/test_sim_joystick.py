"""Kinova joystick semantics: mode cycling, counters, function -> twist/finger mapping."""
import numpy as np
import pytest

from sim.joystick import ArmCommand, JoystickInterpreter, JoystickState, Mode

B1 = JoystickState(pressed=frozenset({"B1"}))
B2 = JoystickState(pressed=frozenset({"B2"}))


@pytest.fixture
def stick():
    return JoystickInterpreter(full_speed=0.2, wrist_speed=0.6)


def test_b1_cycles_translation_wrist_fingers_and_back(stick):
    seen = [stick.mode]
    for _ in range(4):
        stick.update(B1)
        seen.append(stick.mode)
    assert seen == [Mode.TRANSLATION, Mode.WRIST, Mode.FINGERS, Mode.TRANSLATION, Mode.WRIST]
    assert (stick.button_presses, stick.mode_switches) == (4, 4)


def test_b2_cycles_the_other_way(stick):
    seen = []
    for _ in range(3):
        stick.update(B2)
        seen.append(stick.mode)
    assert seen == [Mode.FINGERS, Mode.WRIST, Mode.TRANSLATION]


def test_both_buttons_in_one_tick_count_two_presses_and_no_switch(stick):
    stick.update(JoystickState(pressed=frozenset({"B1", "B2"})))
    assert stick.mode is Mode.TRANSLATION
    assert (stick.button_presses, stick.mode_switches) == (2, 0)


def test_holding_a_function_or_nothing_does_not_count_presses(stick):
    for _ in range(10):
        stick.update(JoystickState({"F": 1.0}))
        stick.update(JoystickState())
    assert (stick.button_presses, stick.mode_switches) == (0, 0)
    stick.reset()
    stick.update(B1)
    stick.reset()
    assert (stick.mode, stick.button_presses, stick.mode_switches) == (Mode.TRANSLATION, 0, 0)


@pytest.mark.parametrize("function, direction", [
    ("F", (0, -1, 0)), ("B", (0, 1, 0)), ("R", (-1, 0, 0)), ("L", (1, 0, 0)), ("Rr", (0, 0, 1)), ("Lr", (0, 0, -1))])
def test_translation_mode_moves_along_the_papers_axes(stick, function, direction):
    command = stick.update(JoystickState({function: 0.5}))
    np.testing.assert_allclose(command.linear, 0.1 * np.array(direction))
    np.testing.assert_allclose(command.angular, 0)
    assert command.finger == 0


def test_axes_combine_and_opposite_functions_cancel(stick):
    command = stick.update(JoystickState({"F": 1.0, "L": 0.5, "Rr": 0.25}))
    np.testing.assert_allclose(command.linear, [0.1, -0.2, 0.05])
    command = stick.update(JoystickState({"F": 0.7, "B": 0.7}))
    np.testing.assert_allclose(command.linear, 0, atol=1e-15)


def test_wrist_mode_rotates_and_does_not_translate(stick):
    stick.update(B1)
    command = stick.update(JoystickState({"F": 1.0, "Rr": 0.5}))
    np.testing.assert_allclose(command.linear, 0)
    np.testing.assert_allclose(command.angular, [-0.6, 0, 0.3])


def test_finger_mode_closes_on_f_opens_on_b_and_ignores_the_rest(stick):
    stick.update(B2)
    assert stick.update(JoystickState({"F": 0.8})).finger == pytest.approx(0.8)
    assert stick.update(JoystickState({"B": 0.3})).finger == pytest.approx(-0.3)
    idle = stick.update(JoystickState({"R": 1.0, "Lr": 1.0}))
    assert idle.finger == 0
    np.testing.assert_allclose(np.concatenate((idle.linear, idle.angular)), 0)


def test_no_function_means_hold_still(stick):
    for state in (JoystickState(), B1, JoystickState()):
        command: ArmCommand = stick.update(state)
        assert not command.linear.any() and not command.angular.any() and command.finger == 0


@pytest.mark.parametrize("bad", [
    dict(deflection={"X": 0.5}), dict(deflection={"F": 1.5}), dict(deflection={"F": -0.1}),
    dict(pressed=frozenset({"B3"}))])
def test_invalid_states_are_rejected(bad):
    with pytest.raises(ValueError):
        JoystickState(**bad)


def test_a_trusted_state_is_the_checked_one_and_the_constructor_still_checks():
    """``JoystickState.trusted`` (internal code's states, unchecked) makes the state the constructor
    makes; a user's state still goes through the constructor's checks."""
    for deflection, pressed in [({"F": 0.25}, frozenset({"B1"})), ({}, frozenset()), ({"Lr": 1.0}, frozenset())]:
        trusted = JoystickState.trusted(dict(deflection), pressed)
        assert trusted == JoystickState(dict(deflection), pressed) and type(trusted.pressed) is frozenset
    assert JoystickState.trusted({}) == JoystickState()
    with pytest.raises(ValueError, match="deflection must be in"):
        JoystickState({"F": 1.5})
    with pytest.raises(ValueError, match="unknown button"):
        JoystickState(pressed={"B3"})


def test_combine_and_layout_tables_equal_the_naive_forms():
    """combine() on floats equals the sum of numpy axis arrays bit for bit; axes() and find() from
    their tables equal a search through the layout's effects."""
    from sim.joystick import FUNCTIONS, LAYOUTS, Kind, combine

    rng = np.random.default_rng(5)
    for layout in LAYOUTS.values():
        for mode in layout.modes:
            for kind in Kind:
                naive_axes = {fn: e.axis for fn, e in layout.effects[mode].items() if e.kind is kind}
                assert dict(layout.axes(mode, kind)) == naive_axes
                for _ in range(20):
                    held = rng.choice(FUNCTIONS, size=rng.integers(0, 4), replace=False)
                    deflection = {str(fn): float(rng.uniform()) for fn in held}
                    if kind is not Kind.FINGERS:
                        total = np.zeros(3)
                        for fn, amount in deflection.items():
                            if fn in naive_axes:
                                total += amount * np.asarray(naive_axes[fn])
                        assert np.array_equal(combine(deflection, layout.axes(mode, kind)), total)
        for mode in layout.modes:
            for fn, effect in layout.effects[mode].items():
                first = next((m, f) for m in layout.modes for f, e in layout.effects[m].items()
                             if e.kind is effect.kind and e.axis == effect.axis)
                assert layout.find(effect.kind, effect.axis) == first
    with pytest.raises(ValueError, match="no function"):
        LAYOUTS["2-axis"].find(Kind.LINEAR, (0.0, 0.0, 0.5))



def test_a_layout_survives_the_queue_that_takes_it_to_the_film_process():
    """`bomi live --video` hands the arm's layout to a spawned process: through a multiprocessing queue
    it must come back with the same cycle, effects and tables (its per-tick tables once could not)."""
    import multiprocessing

    from sim.joystick import LAYOUTS, Kind

    channel = multiprocessing.get_context("spawn").Queue()
    for layout in LAYOUTS.values():
        channel.put(layout)
        copy = channel.get(timeout=10)
        assert copy.name == layout.name and copy.modes == layout.modes and copy.effects == layout.effects
        for mode in layout.modes:
            for kind in Kind:
                assert dict(copy.axes(mode, kind)) == dict(layout.axes(mode, kind))
    channel.close()
