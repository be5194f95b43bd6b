"""progress= of the long calls: a callable sees every step's progress; its exception stops the
work and is raised; anything else is refused."""

import pytest

import ferret


def test_a_callable_sees_each_step_from_start_to_end(houses):
    calls = []

    def record(what, done, total):
        calls.append((what, done, total))

    ev = ferret.evaluate(houses[:3], ["model/uniform"], progress=record)
    assert len(ev) == 3
    houses_calls = [c for c in calls if c[0] == "houses"]
    assert houses_calls[0][1] == 0, "called when the step begins"
    assert houses_calls[-1] == ("houses", 3, 3), "and when it ends, every house done"
    done = [c[1] for c in houses_calls]
    assert done == sorted(done)


def test_the_same_rows_with_or_without_progress(houses):
    quiet = ferret.evaluate(houses[:2], ["model/uniform"])
    shown = ferret.evaluate(houses[:2], ["model/uniform"], progress=lambda *a: None)
    assert quiet.rows == shown.rows


def test_an_exception_of_the_callable_stops_the_work_and_is_raised(houses):
    class Stop(Exception):
        pass

    def stop(what, done, total):
        raise Stop(f"{what} {done}/{total}")

    with pytest.raises(Stop):
        ferret.evaluate(houses[:2], ["model/uniform"], progress=stop)


def test_progress_must_be_a_flag_or_a_callable(houses):
    with pytest.raises(TypeError, match="progress"):
        ferret.evaluate(houses[:1], ["model/uniform"], progress="yes")
    # False and None show nothing, as before.
    assert len(ferret.evaluate(houses[:1], ["model/uniform"], progress=False)) == 1
    assert len(ferret.evaluate(houses[:1], ["model/uniform"], progress=None)) == 1
