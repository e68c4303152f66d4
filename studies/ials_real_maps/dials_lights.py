"""Where one learner loses to another on a map, light by light, beside each light's region.

For every light: the protocol's GS return (``per_agent_scores`` of each result file, the mean
over the files of a group), the difference of the last group from the first, and what its
region (:func:`ials_zoo.sumo_net.regions.regions_of`) holds: its incoming chains' lengths (m;
a chain ends at the upstream junction or at 200 m) and the lights whose regions feed it or are
fed by it. Printed as a Markdown table, largest loss first, with each light's share of the
total difference.

Usage: python studies/ials_real_maps/dials_lights.py NET LABEL=RESULT[,RESULT...] LABEL=RESULT[,RESULT...] ...

    python studies/ials_real_maps/dials_lights.py ingolstadt21 \\
        "IPPO=leaderboard/results/sumo_net_v0__21-agents__ippo__gs__90825f83bcd7.json" \\
        "DIALS=runs/dials_ar/ingolstadt21_s0/result.json,runs/dials_ar/ingolstadt21_r4096_s0/result.json"

Result files are read with the leaderboard's limits (:func:`ials_zoo.leaderboard.validate.load_result`).
"""

import sys

import numpy as np

from ials_zoo.leaderboard.validate import load_result


def group_scores(spec: str) -> tuple[str, dict[str, float]]:
    """``LABEL=FILE[,FILE...]`` -> the label and, per light, the mean of the files' scores."""
    label, _, files = spec.partition("=")
    if not label or not files:
        raise SystemExit(__doc__)
    per_file = [load_result(path)["per_agent_scores"] for path in files.split(",")]
    lights = set(per_file[0]).intersection(*per_file[1:])
    return label, {light: float(np.mean([scores[light] for scores in per_file])) for light in lights}


def region_facts(net: str) -> dict[str, tuple[list[int], list[str]]]:
    """Per light: its chains' lengths (m) and the lights whose regions touch its own."""
    import sumolib

    from ials_zoo.sumo_net.regions import regions_of
    from ials_zoo.sumo_net.scenario import make_scenario

    net_file = make_scenario(net=net).net_file
    regions, graph = regions_of(net_file), sumolib.net.readNet(net_file)
    feeds = {light: set(r.incoming).union(*map(set, r.chains)) for light, r in regions.items()}
    leaves = {light: set(r.outgoing) | set(r.beyond) for light, r in regions.items()}
    facts = {}
    for light, region in regions.items():
        lengths = [round(sum(graph.getEdge(e).getLength() for e in chain)) for chain in region.chains]
        touching = sorted(other for other in regions if other != light
                          and (leaves[light] & feeds[other] or leaves[other] & feeds[light]))
        facts[light] = (lengths, touching)
    return facts


def table(net: str, groups: list[tuple[str, dict[str, float]]]) -> str:
    """The Markdown table of the module docstring."""
    facts = region_facts(net)
    first, last = groups[0][1], groups[-1][1]
    lights = sorted(set(first) & set(last), key=lambda light: last[light] - first[light])
    total = sum(last[light] - first[light] for light in lights)
    head = " | ".join(label for label, _ in groups)
    rows = [f"| light | {head} | last - first (share) | chains (m) | lights beside |",
            "|---|" + "---|" * (len(groups) + 3)]
    for light in lights:
        diff = last[light] - first[light]
        lengths, touching = facts.get(light, ([], []))
        scores = " | ".join(f"{scores[light]:.1f}" for _, scores in groups)
        rows.append(f"| {light[:24]} | {scores} | {diff:.1f} ({diff / total:.0%}) | {lengths} | "
                    f"{', '.join(t[:14] for t in touching) or '-'} |")
    rows.append("| all lights (sum) | " + " | ".join(f"{sum(s[light] for light in lights):.1f}" for _, s in groups)
                + f" | {total:.1f} | | |")
    return "\n".join(rows)


def main(argv: list[str]) -> None:
    if len(argv) < 3:
        raise SystemExit(__doc__)
    import sumo  # noqa: F401  (sets SUMO_HOME for sumolib)

    print(table(argv[0], [group_scores(spec) for spec in argv[1:]]))


if __name__ == "__main__":
    main(sys.argv[1:])
