"""traffic_grid_v0: the fast paths of the per-step code give the plain results.

Light bookkeeping of many copies with overlapping yellows (checked against the light state
SUMO actually runs), the int fast path of the action check, and the LS's action check.
"""

import numpy as np
import pytest

from ials_zoo.traffic.env import check_action
from ials_zoo.traffic.local import TrafficLocalSimulator


def _reference_phases(actions):
    """Keep/switch with a 3-step yellow, written out plainly: phase after each step."""
    phase, left, out = 0, 0, []
    for a in actions:
        if a and phase % 2 == 0:
            phase, left = phase + 1, 3
        if left:
            left -= 1
            if not left:
                phase = (phase + 1) % 4
        out.append(phase)
    return out


def test_overlapping_yellows_of_many_copies():
    n, T = 5, 30
    rng = np.random.default_rng(3)
    acts = (rng.random((T, n)) < 0.4).astype(np.int64)
    acts[0] = 1  # all switch at once, then staggered
    ls = TrafficLocalSimulator("tls_12", n_envs=n, max_cycles=T)
    try:
        ls.reset(seed=0)
        states = ls.files.meta["states"]
        seen = []
        for t in range(T):
            obs, _, _ = ls.step(acts[t], np.zeros((n, 4), np.int64))
            phases = obs[:, 36:].argmax(1)
            seen.append(phases)
            for k in range(n):
                # the state SUMO will run next step is the one the observation shows
                sumo = ls.sumo_query("trafficlight", "getRedYellowGreenState", f"c{k}")
                assert sumo == states[f"c{k}"][phases[k]], (t, k)
        seen = np.array(seen)
        for k in range(n):
            assert seen[:, k].tolist() == _reference_phases(acts[:, k].tolist()), k
        assert len(set(map(tuple, seen.tolist()))) > 3  # the copies really were out of step
    finally:
        ls.close()


def test_check_action_fast_path_keeps_the_errors():
    assert check_action("tls_0", 0) == 0 and check_action("tls_0", 1) == 1
    assert check_action("tls_0", np.int64(1)) == 1
    assert check_action("tls_0", np.array(1)) == 1
    for bad, exc in [(True, TypeError), (np.bool_(True), TypeError), (2, ValueError),
                     (-1, ValueError), (1.0, TypeError)]:  # fmt: skip
        with pytest.raises(exc, match="tls_0"):
            check_action("tls_0", bad)


@pytest.mark.parametrize("n", [1, 3])
def test_ls_action_check(n):
    ls = TrafficLocalSimulator("tls_12", n_envs=n, max_cycles=5)
    try:
        ls.reset(seed=0)
        zero = np.zeros((n, 4), np.int64)
        for bad in (2, -1, 7):
            a = np.zeros(n, np.int64)
            a[-1] = bad
            with pytest.raises(ValueError, match="0 .keep. or 1"):
                ls.step(a, zero)
        ls.step(np.ones(n, np.uint8), zero)  # unsigned ints are fine
    finally:
        ls.close()
