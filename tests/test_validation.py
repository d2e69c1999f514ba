"""The boundary checks every public function shares."""

import numpy as np
import pytest

from posedrift._validation import check_rng, check_scalar


@pytest.mark.parametrize("seed", [0, 1, 12345, 2**40, np.int64(7), True])
def test_an_int_seed_gives_numpys_stream_for_that_seed_every_time(seed):
    for _ in range(2):  # each call starts the stream afresh
        got = check_rng(seed)
        want = np.random.default_rng(seed)
        assert np.array_equal(got.random(100), want.random(100))
        assert np.array_equal(
            got.choice(700, 400, replace=False), want.choice(700, 400, replace=False)
        )


def test_a_generator_is_used_as_given_and_bad_seeds_are_refused():
    gen = np.random.default_rng(3)
    assert check_rng(gen) is gen
    assert isinstance(check_rng(None), np.random.Generator)
    with pytest.raises(ValueError, match="non-negative"):
        check_rng(-1)
    with pytest.raises(ValueError, match="'rng' argument must be an int"):
        check_rng(0.5)


@pytest.mark.parametrize(
    ("value", "kwargs", "expected"),
    [
        (0.5, {"low": 0.0}, 0.5),
        (0.0, {"low": 0.0, "include_low": True}, 0.0),
        (np.inf, {"low": 0.0}, np.inf),
        (3, {"low": 1, "integer": True}, 3),
        (1.0, {"high": 1.0, "include_high": True}, 1.0),
    ],
)
def test_check_scalar_accepts_values_inside_the_interval(value, kwargs, expected):
    assert check_scalar(value, "x", **kwargs) == expected


@pytest.mark.parametrize(
    ("value", "kwargs", "message"),
    [
        (0.0, {"low": 0.0}, r"must be a float in \(0, inf\)\. Got 0\.0 instead"),
        (-1, {"low": 0.0, "include_low": True}, r"in \[0, inf\)\. Got -1 instead"),
        (np.nan, {}, r"a float in \(-inf, inf\)\. Got nan instead"),
        (np.inf, {"high": 2.0}, r"in \(-inf, 2\)\. Got inf instead"),
        (True, {}, "Got True instead"),
        ("a", {}, "Got 'a' instead"),
        (2.5, {"integer": True}, r"must be an int in \(-inf, inf\)\. Got 2\.5"),
        (1.0, {"high": 1.0}, r"in \(-inf, 1\)\. Got 1\.0"),
    ],
)
def test_check_scalar_names_the_parameter_the_interval_and_the_value(value, kwargs, message):
    with pytest.raises(ValueError, match="The 'x' parameter of f must be") as info:
        check_scalar(value, "x", caller="f", **kwargs)
    info.match(message)


def test_median_has_np_median_bits():
    from posedrift._stats import median

    rng = np.random.default_rng(0)
    for trial in range(400):
        n = int(rng.integers(1, 60))
        values = rng.normal(size=n) * [1e-40, 1.0, 1e30][trial % 3]
        if trial % 4 == 0:
            values = np.round(values, 1)  # ties and signed zeros
        for array in (values, values.astype(np.float32), np.column_stack([values] * 3)[:, 1]):
            expected = float(np.median(array))
            assert np.float64(median(array)).tobytes() == np.float64(expected).tobytes()
