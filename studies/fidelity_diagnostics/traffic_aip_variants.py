"""Diagnostic: traffic on-policy AIP variants in the fidelity report (architecture, hidden units,
d-set kind, GS steps), all autoregressive reading their last draw only (the variants were
measured before traffic's AIPs read 3), lr 3e-3 decayed linearly to zero.

    python studies/fidelity_diagnostics/traffic_aip_variants.py POLICIES SEED ARCH HIDDEN DSET_KIND STEPS EPOCHS BATCH

e.g. the IPPO lights with MLPs of 32 hidden units, or GRUs over the d-set history, or MLPs that
also read the light's own state (the ``full`` d-set):

    P=leaderboard/policies/0f22715d32627b9c6b2e3a00514da869d8737da43dccfb7107d3949f8e7d985e.safetensors
    python studies/fidelity_diagnostics/traffic_aip_variants.py $P 0 mlp 32 dset 10000 30 256
    python studies/fidelity_diagnostics/traffic_aip_variants.py $P 0 gru 64 dset 10000 60 8
    python studies/fidelity_diagnostics/traffic_aip_variants.py $P 0 mlp 128 full 10000 30 256
"""

import sys

import torch

torch.set_num_threads(1)
from ials_zoo.influence import fidelity as F
from ials_zoo.influence.dataset import collect_all
from ials_zoo.influence.train import train_predictors

policies = sys.argv[1].split(",")
seed = int(sys.argv[2])
arch, hidden, kind = sys.argv[3], int(sys.argv[4]), sys.argv[5]
steps, epochs, batch = int(sys.argv[6]), int(sys.argv[7]), int(sys.argv[8])


def aips(env_id, agents, policy, _steps, seed, autoregressive, options, *_, **__):
    if policy == "random":
        actor = None
    elif policy == "constant":
        actor = {a: (lambda obs: 0) for a in agents}
    else:
        actor = F._PolicyActor(policy, agents, seed)
    data = collect_all(env_id, agents, steps=steps, policy=actor, seed=seed, gs_options=options, progress=False)
    preds, rep = train_predictors(
        data,
        arch,
        hidden=hidden,
        lr=3e-3,
        epochs=epochs,
        batch_size=batch,
        seed=seed,
        autoregressive=autoregressive,
        dset_kind=kind,
    )
    print(f"training {rep['train_seconds']:.0f} s, held-out cross-entropy {rep['mean_test_cross_entropy']:.4f}")
    return preds


F.on_policy_aips = aips
rep = F.fidelity_report(
    "traffic_grid_v0", policies, episodes=10, seed=seed, predictor="on-policy-autoregressive", progress=False
)
for name, rows in rep["policies"].items():
    for a, ms in rows.items():
        print(
            name[-12:],
            a,
            " ".join(
                f"{m}: {c['gs']:.1f} / {c['ials']:.1f}{'' if c['holds'] in (True, None) else ' (fails)'}"
                for m, c in ms.items()
                if m in ("arrivals", "gap", "return")
            ),
        )
n = sum(r["holds"] for p in rep["policies"].values() for a in p.values() for r in a.values() if r["holds"] is not None)
print("rows that hold", n)
