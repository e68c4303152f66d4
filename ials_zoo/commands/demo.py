"""``ials-zoo demo``: run one episode of a domain's global simulator and summarise it.

One agent (default: the domain's first paper agent) acts uniformly at random; every other
agent follows the domain's scripted controller. Prints what happened (the random agent's
return and the domain's own figures, e.g. items collected or vehicles in the network) and the
speed; ``--gif`` also saves the episode as an animated GIF with the step, the agent's reward
and return, and a colour legend on every frame.
"""

from __future__ import annotations

import os
import time

import numpy as np

from ials_zoo.commands import NET_HELP, CommandError, with_network
from ials_zoo.core.domains import default_domain, domain_ids, get_domain
from ials_zoo.core.extras import viewer_of
from ials_zoo.utils import check_output_file
from ials_zoo.viewer import annotate, save_gif


def configure(parser):
    parser.add_argument("--domain", default=None, choices=domain_ids(),
                        help=f"which domain (default: {default_domain()})")
    parser.add_argument("--steps", type=int, default=None,
                        help="episode length in steps (default: the domain's episode length)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    parser.add_argument("--agent", default=None,
                        help="the randomly acting agent (default: the domain's first paper agent)")
    parser.add_argument("--net", default=None, metavar="NAME", help=NET_HELP)
    parser.add_argument("--sumocfg", default=None, metavar="PATH",
                        help="a network of your own instead of --net (a domain that takes files: sumo_net_v0)")
    parser.add_argument("--gif", default=None, metavar="PATH",
                        help="save the episode as an animated GIF here")


def run(args) -> int:

    domain = get_domain(args.domain or default_domain())
    steps = domain.episode_length if args.steps is None else args.steps
    if steps < 1:
        raise CommandError(f"--steps must be >= 1, got {steps}")
    if args.seed < 0:
        raise CommandError(f"--seed must be >= 0, got {args.seed}")
    network = with_network(domain, {}, args.net)
    if args.sumocfg is not None:
        if "sumocfg" not in domain.file_options:
            raise CommandError(f"--sumocfg: {domain.env_id} takes no network of your own")
        if args.net is not None:
            raise CommandError("--net and --sumocfg both name a network; give one")
        if not os.path.isfile(args.sumocfg):
            raise CommandError(f"--sumocfg: no such file {args.sumocfg!r}")
        network = domain.with_absolute_files({"sumocfg": args.sumocfg})
    try:
        agent = args.agent or (domain.agents(**network)[0] if network else domain.default_agents[0])
        domain.check_agent(agent, **network)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    if args.gif:
        check_output_file(args.gif, "--gif")
    options = {"learners": [agent], "max_cycles": steps, **network}
    if args.gif:
        options["render_mode"] = "rgb_array"
    env = domain.parallel_env(**options)

    frames = []
    rng = np.random.default_rng(args.seed)
    total, t = 0.0, 0
    try:
        env.reset(seed=args.seed)
        space = env.action_space(agent)
        space.seed(int(rng.integers(2**31)))
        legend = viewer_of(domain).legend
        if args.gif:

            frames.append(annotate(env.render(), f"{domain.env_id}  step 0/{steps}", legend))
        t0 = time.perf_counter()
        render_time = 0.0
        while env.agents:
            _, rewards, _, _, _ = env.step({agent: space.sample()})
            reward = float(rewards[agent])
            total += reward
            t += 1
            if args.gif:
                t1 = time.perf_counter()
                caption = f"{domain.env_id}  step {t}/{steps}  {agent} reward {reward:.2f}, return {total:.2f}"
                frames.append(annotate(env.render(), caption, legend))
                render_time += time.perf_counter() - t1
        elapsed = time.perf_counter() - t0 - render_time
        summary = {f"return of {agent} (random)": f"{total:.3f}"}
        if viewer_of(domain).episode_summary is not None:
            summary.update(viewer_of(domain).episode_summary(env))
        summary["GS steps/s"] = f"{t / max(elapsed, 1e-9):,.0f}"
    finally:
        env.close()

    print(f"{domain.env_id}: {t} steps, seed {args.seed}, {agent} random, others scripted")
    for key, value in summary.items():
        print(f"  {key:<30} {value}")
    if args.gif:

        fps = float(env.metadata.get("render_fps", 5))
        save_gif(frames, args.gif, fps=fps)
        print(f"  {'gif':<30} {args.gif} ({len(frames)} frames, {fps:g} per second)")
    return 0
