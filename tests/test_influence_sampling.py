"""The stacked AIPs and their random streams checked against what they must compute: training
lowers every source's cross-entropy, sampled frequencies match the predicted probabilities
(chi-square), refreshed AIPs reach the DIALS shards, and every copy draws its own numbers."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

ENV = "warehouse_v0"
OPTIONS = {"robots": (2, 2)}
AGENTS = ["robot_0", "robot_1", "robot_2", "robot_3"]


@pytest.fixture(scope="module")
def datasets():
    from ials_zoo.influence.dataset import collect_all

    return collect_all(ENV, AGENTS, steps=1000, seed=2, gs_options=OPTIONS, progress=False)


@pytest.mark.parametrize("arch", ["mlp", "gru"])
def test_stacked_training_lowers_every_sources_cross_entropy(datasets, arch):
    """Every source of every agent is in the loss: each one's cross-entropy falls well below
    the untrained network's (a source left out of the loss keeps its untrained head)."""
    from ials_zoo.influence.metrics import cross_entropy_per_source
    from ials_zoo.influence.train import train_predictors

    kw = {"mlp": dict(epochs=8, lr=1e-2), "gru": dict(epochs=15, lr=1e-2, batch_size=2)}[arch]
    before, _ = train_predictors(datasets, arch, hidden=16, seed=0, **dict(kw, epochs=1, lr=1e-12))
    after, _ = train_predictors(datasets, arch, hidden=16, seed=0, **kw)
    for a in AGENTS:
        ce0 = cross_entropy_per_source(before[a], datasets[a])
        ce1 = cross_entropy_per_source(after[a], datasets[a])
        # every region here has 2 real neighbours and 2 missing ones (always "none"): the
        # trained CE of each source is a fraction of the untrained ~1.4 nats
        assert np.all(ce1 < 0.75 * ce0), (a, ce0, ce1)


def _chi_square_p(counts: np.ndarray, probs: np.ndarray) -> float:
    keep = probs > 0
    assert counts[~keep].sum() == 0, "a class of probability 0 was sampled"
    expected = probs[keep] / probs[keep].sum() * counts.sum()
    return float(stats.chisquare(counts[keep], expected).pvalue)


@pytest.mark.parametrize("kind", ["network", "table"])
def test_stacked_samples_follow_the_predicted_probabilities(datasets, kind):
    from ials_zoo.influence.multi import resolve_predictor_set
    from ials_zoo.influence.stacked import StackedPredictor
    from ials_zoo.influence.train import train_predictors

    if kind == "network":
        preds, _ = train_predictors(datasets, "mlp", hidden=16, epochs=2, lr=1e-2, seed=0)
        preds = [preds[a] for a in AGENTS]
    else:
        preds = resolve_predictor_set("uniform", ENV, AGENTS, seed=0, options=OPTIONS)
    n_envs, draws = 5, 4000
    stacked = StackedPredictor(preds, n_envs=n_envs)
    stacked.seed(11)
    d = np.stack([np.repeat(datasets[a].dsets["dset"][0][7][None], n_envs, axis=0) for a in AGENTS])
    d = d.reshape(len(AGENTS) * n_envs, -1)
    probs = stacked.probs_padded(d)  # [rows, M, K], the same at every step (a memoryless AIP)
    K = probs.shape[-1]
    counts = np.zeros(probs.shape)
    for _ in range(draws):
        u = stacked.sample(d)
        np.put_along_axis(counts, u[..., None], np.take_along_axis(counts, u[..., None], -1) + 1, -1)
    pvalues = [_chi_square_p(counts[r, m], probs[r, m]) for r in range(len(d)) for m in range(probs.shape[1])
               if (probs[r, m] > 0).sum() > 1]
    assert pvalues and K >= 2
    # 80 tests at level 0.001: a correct sampler fails one with probability < 0.08
    assert min(pvalues) > 1e-3, sorted(pvalues)[:3]


def test_copies_of_one_agent_draw_different_numbers():
    from ials_zoo.core.domains import get_domain
    from ials_zoo.core.streams import CopyStreams

    streams = CopyStreams(["robot_0", "robot_1"], 3, 4)
    streams.seed(5)
    rows = np.stack([streams.next().copy() for _ in range(10)])  # [t, rows, width]
    for i in range(6):
        for j in range(i + 1, 6):
            assert not np.allclose(rows[:, i], rows[:, j]), (i, j)
    # copies of one region in a batched local simulator, driven alike, live different episodes
    ls = get_domain(ENV).local_simulator("robot_0", n_envs=3, **OPTIONS)
    ls.reset(seed=1)
    for _ in range(40):
        ls.step(np.zeros(3, np.int64), np.full((3, 4), 3, np.int64))
    ages = ls.get_state()[1]  # [copies, 12] item ages
    assert not np.array_equal(ages[0], ages[1]) and not np.array_equal(ages[1], ages[2]), ages


def test_refreshed_aips_reach_the_shards(datasets, tmp_path):
    """After set_predictors, every worker's shard samples from the new AIPs: their weights are
    those of the new set (and not the ones the shards started with)."""
    from ials_zoo.baselines.dials import Args, check_args
    from ials_zoo.baselines.multiagent import ppo_config
    from ials_zoo.dials.backends import make_backend
    from ials_zoo.dials.shard import ShardSpec, split_agents
    from ials_zoo.influence.train import train_predictors

    args = Args(env_id=ENV, agents=",".join(AGENTS), env_options=json.dumps(OPTIONS), n_envs=2, progress=False)
    _, agents, options, _, copies = check_args(args)
    start, _ = train_predictors(datasets, "gru", hidden=8, epochs=1, seed=0)
    new, _ = train_predictors(datasets, "gru", hidden=8, epochs=2, lr=1e-2, seed=1)
    specs = [ShardSpec(ENV, chunk, options, 0, copies, 1, "batched", ppo_config(args, copies), 10,
                       predictors={a: start[a] for a in chunk}) for chunk in split_agents(agents, 2)]
    backend = make_backend("process", specs)
    try:
        backend.call("set_predictors", [(new,)] * len(specs))
        held = {a: p for shard in backend.call("predictors") for a, p in shard.items()}
    finally:
        backend.close()
    assert sorted(held) == sorted(AGENTS)
    for a in AGENTS:
        for k, w in new[a]._arrays().items():
            np.testing.assert_array_equal(held[a][k], w, err_msg=f"{a} {k}")
        assert any(not np.array_equal(held[a][k], w) for k, w in start[a]._arrays().items())
