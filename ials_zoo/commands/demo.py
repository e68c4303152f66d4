"""``ials-zoo demo``: run one short episode of a domain's global simulator and summarise it.

The domain's first default agent (``robot_20`` in the warehouse) acts uniformly at random;
every other agent follows the domain's scripted controller. Prints what happened (items
collected, the random agent's return, the scripted agents' mean return) and the speed;
``--gif`` also saves the episode as an animated GIF.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from ials_zoo.core.domains import domain_ids, get_domain


def configure(parser):
    parser.add_argument("--domain", default="warehouse_v0", choices=domain_ids(),
                        help="which domain (default: warehouse_v0)")
    parser.add_argument("--steps", type=int, default=100,
                        help="episode length in steps (default: 100)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    parser.add_argument("--agent", default=None,
                        help="the randomly acting agent (default: the domain's first default agent)")
    parser.add_argument("--gif", default=None, metavar="PATH",
                        help="save the episode as an animated GIF here")


def run(args) -> int:
    if args.steps < 1:
        print(f"ials-zoo demo: --steps must be >= 1, got {args.steps}", file=sys.stderr)
        return 2
    try:
        domain = get_domain(args.domain)
    except ImportError as exc:
        print(f"ials-zoo demo: domain {args.domain!r} is not available here: {exc}", file=sys.stderr)
        return 1
    agent = args.agent or domain.default_agents[0]
    if agent not in domain.possible_agents():
        print(f"ials-zoo demo: unknown agent {agent!r} for {args.domain}", file=sys.stderr)
        return 2
    options = {"learners": [agent], "max_cycles": args.steps}
    if args.gif:
        options["render_mode"] = "rgb_array"
    try:
        env = domain.parallel_env(**options)
    except (ImportError, RuntimeError, OSError) as exc:
        print(f"ials-zoo demo: cannot start {args.domain}: {exc}", file=sys.stderr)
        return 1

    frames = []
    rng = np.random.default_rng(args.seed)
    learner_return, steps = 0.0, 0
    try:
        env.reset(seed=args.seed)
        env.action_space(agent).seed(int(rng.integers(2**31)))
        if args.gif:
            frames.append(env.render())
        t0 = time.perf_counter()
        render_time = 0.0
        while env.agents:
            _, rewards, _, _, _ = env.step({agent: env.action_space(agent).sample()})
            learner_return += float(rewards[agent])
            steps += 1
            if args.gif:
                t1 = time.perf_counter()
                frames.append(env.render())
                render_time += time.perf_counter() - t1
        elapsed = time.perf_counter() - t0 - render_time
        summary = _summary(env, agent, learner_return, steps, elapsed)
    finally:
        env.close()

    print(f"{args.domain}: {steps} steps, seed {args.seed}, {agent} random, others scripted")
    for key, value in summary:
        print(f"  {key:<28} {value}")
    if args.gif:
        from ials_zoo.warehouse.render import save_gif

        save_gif(frames, args.gif)
        print(f"  {'gif':<28} {args.gif} ({len(frames)} frames)")
    return 0


def _summary(env, agent, learner_return, steps, elapsed):
    rows = []
    if hasattr(env, "items_collected"):
        rows.append(("items collected (all robots)", env.items_collected))
    rows.append((f"return of {agent} (random)", f"{learner_return:.3f}"))
    returns = getattr(env, "episode_returns", None)
    if returns is not None and len(returns) > 1:
        scripted = np.delete(np.asarray(returns, dtype=float), env._learner_idx)
        rows.append(("mean return, scripted", f"{scripted.mean():.3f} (n={len(scripted)})"))
    rows.append(("GS steps/s", f"{steps / max(elapsed, 1e-9):,.0f}"))
    return rows
