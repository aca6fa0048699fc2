"""wait_until, the one way a test waits: it hands back the condition's first truthy value, and a
wait that runs out fails saying what it waited for and what it saw last."""

import itertools

import pytest
from polling import wait_until


def test_it_returns_the_first_truthy_value_of_the_condition():
    calls = itertools.count(1)
    assert wait_until(lambda: (n := next(calls)) >= 3 and f"call {n}", every=0) == "call 3"


def test_a_wait_that_runs_out_names_what_it_waited_for_and_what_it_saw_last():
    with pytest.raises(AssertionError, match=r"timed out after 0.05 s waiting for the job \(last: \[\]\)"):
        wait_until(lambda: [], 0.05, what="the job", every=0.01)


def test_what_may_be_a_function_asked_only_when_the_wait_runs_out():
    asked = []

    def state():
        asked.append(1)
        return "job 7 still processing"

    with pytest.raises(AssertionError, match="waiting for job 7 still processing"):
        wait_until(lambda: None, 0.05, what=state, every=0.01)
    assert asked == [1]


def test_exceptions_it_is_told_to_ignore_count_as_not_yet():
    calls = itertools.count(1)

    def flaky():
        if next(calls) < 3:
            raise LookupError("not on the page yet")
        return "there"

    assert wait_until(flaky, 1, every=0, ignoring=LookupError) == "there"
    with pytest.raises(KeyError):  # any other exception is the test's failure, at once
        wait_until(lambda: {}["x"], 1, ignoring=ValueError)
