"""``ials-zoo collect``: record ``(d_t, u_t)`` data of one agent from its GS (Algorithm 1).

Example::

    ials-zoo collect --env warehouse_v0 --agent robot_20 --steps 50000 --out wh.npz

The learning agent follows a uniformly random policy, every other agent is scripted. The
output is an :class:`ials_zoo.influence.InfluenceDataset` ``.npz`` file (format documented in
``ials_zoo.influence.dataset``).
"""

from __future__ import annotations



def _json_dict(text: str) -> dict:
    from ials_zoo.utils import parse_json_object

    try:
        return parse_json_object(text, "--options")
    except ValueError as exc:
        raise SystemExit(f"ials-zoo: {exc}") from None


def add_collect_arguments(parser, required: bool = True) -> None:
    """Arguments shared by ``collect`` and ``train-aip``."""
    from ials_zoo.core.domains import domain_ids

    parser.add_argument("--env", required=required, choices=domain_ids(), help="domain id")
    parser.add_argument("--agent", required=required, help="learning agent, e.g. robot_20")
    parser.add_argument("--steps", type=int, default=50_000,
                        help="steps to record, rounded up to whole episodes (default 50000)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--options", default="{}",
                        help='GS options as JSON, e.g. \'{"item_lifetime": 8}\'')
    parser.add_argument("--workers", type=int, default=1,
                        help="GS processes collecting at once (each records steps/workers; worth it for SUMO)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def configure(parser):
    add_collect_arguments(parser)
    parser.add_argument("--out", required=True, help="output .npz file")


def run(args) -> int:
    from ials_zoo.influence.dataset import collect

    options = _json_dict(args.options)
    try:
        data = collect(args.env, args.agent, steps=args.steps, seed=args.seed, gs_options=options,
                       progress=not args.no_progress, workers=args.workers)
    except ValueError as exc:
        raise SystemExit(f"ials-zoo collect: {exc}") from None
    data.save(args.out)
    m = data.metadata
    print(
        f"wrote {args.out}: {data.n_episodes} episodes x {data.episode_length} steps of "
        f"{args.env}/{args.agent} ({m['collect_seconds']:.1f} s, "
        f"{data.n_steps / max(m['collect_seconds'], 1e-9):,.0f} steps/s)"
    )
    return 0
