"""Checks shared by the tests that compare two training runs bit for bit."""

import numpy as np


def policy_weights(folder) -> dict:
    from safetensors.numpy import load_file

    return load_file(folder / "policy.safetensors")


def assert_same_run(a, b):
    """``a``, ``b``: ``(result, run folder)``. Bitwise the same weights, learning curve and
    scores (the policy files themselves differ in their recorded wall-clocks)."""
    (ra, fa), (rb, fb) = a, b
    wa, wb = policy_weights(fa), policy_weights(fb)
    assert wa.keys() == wb.keys()
    for k in wa:
        np.testing.assert_array_equal(wa[k], wb[k], err_msg=k)
    assert [p["mean"] for p in ra["learning_curves"][0]["points"]] == \
        [p["mean"] for p in rb["learning_curves"][0]["points"]]
    for key in ("returns", "per_agent_returns"):  # a single-agent result has no per-agent returns
        assert [s.get(key) for s in ra["scores"]] == [s.get(key) for s in rb["scores"]]
    assert ra["score"] == rb["score"]
