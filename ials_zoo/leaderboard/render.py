"""Showing the board: a text table (``show``) and ``README.md`` with learning-curve plots
(``render``), per track and domain, official entries apart from protocol variants and from the
archive."""

from __future__ import annotations

import html
import re
from pathlib import Path

import numpy as np

from ials_zoo import reference_speed
from ials_zoo.core.domains import get_domain
from ials_zoo.errors import BadInput
from ials_zoo.leaderboard.build import MULTI, OFFICIAL, SINGLE
from ials_zoo.leaderboard.store import ARCHIVE_SUBDIR, board_path, load_entries
from ials_zoo.stats import iqm_interval
from ials_zoo.utils import atomic_path, atomic_write_text, format_seconds, read_regular_file

WRITEUP = "writeup.md"
MAX_WRITEUP_BYTES = 1 << 20
HEADER = ["policy / algorithm", "trained on", "GS score", "95% CI", "IQM [95% CI]", "seeds", "episodes",
          "env steps", "wall-clock (+AIP) [on the reference machine]", "date"]
UNDER_LOAD = "timed under load"


def _training_label(data: dict) -> str:
    return "-" if data["training"] is None else data["training"]["simulator"]


def _total_seconds(data: dict) -> float | None:
    t = data["training"]
    return None if t is None else float(t["wall_clock_seconds"]) + float(t["aip_seconds"])


def format_duration(seconds: float) -> str:
    return format_seconds(seconds, hour_decimals=2)


def wall_clock_text(data: dict) -> str:
    """An entry's wall-clock (training and AIPs), then the same in seconds of the reference
    machine where the run measured its machine's speed (:mod:`ials_zoo.reference_speed`), and
    a mark where that speed moved by more than 20% during the run."""
    total = _total_seconds(data)
    if total is None:
        return "-"
    ref = reference_speed.of(data["training"])
    if ref is None:
        return format_duration(total)
    return (f"{format_duration(total)} [{format_duration(ref['reference_seconds'])}]"
            + (f" ({UNDER_LOAD})" if ref["under_load"] else ""))


def _iqm(d: dict) -> str:
    """The IQM of the seeds' scores with its bootstrap interval (several seeds only)."""
    if len(d["scores"]) < 2:
        return "-"
    point, lo, hi = iqm_interval([[s["mean"] for s in d["scores"]]])
    return f"{point:.2f} [{lo:.2f}, {hi:.2f}]"


def console_text(text) -> str:
    """User text for a terminal: every character that is not printable (a newline, a carriage
    return, an escape sequence's ESC) written as its escape, so that no entry can add or
    rewrite console rows."""
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in str(text))


def _row(d: dict) -> list[str]:
    s, t = d["score"], d["training"]
    label = d["algorithm"] + (" (deterministic)" if d["evaluation"].get("deterministic") else "")
    if d["policy"]["kind"] == "rule":
        label += " (rule)"
    if d.get("provenance") == "external":
        label += " [external: training claims unverified]"
    if d.get("retrained"):
        label += " [re-trained]"
    return [console_text(label), console_text(_training_label(d)), f"{s['mean']:.2f}",
            f"[{s['ci_low']:.2f}, {s['ci_high']:.2f}]", _iqm(d), str(len(d["scores"])) if t else "-",
            str(d["evaluation"]["episodes"]), f"{t['env_steps']:,}" if t else "-",
            wall_clock_text(d), console_text(d["created"][:10])]


def metric_text(m: dict | None) -> str:
    """A metric's cell: mean [95% CI], and its median where the result keeps one (a gridlocked
    episode moves the mean, not the median)."""
    if m is None:
        return "-"
    text = f"{m['mean']:.2f} [{m['ci_low']:.2f}, {m['ci_high']:.2f}]"
    return text + (f"; median {m['median']:.2f}" if "median" in m else "")


def ranking_metric(env_id: str) -> str | None:
    """The metric that ranks a domain's entries (:attr:`Domain.score_metric`), or None: the score."""
    return get_domain(env_id).score_metric


def sort_key(sort: str):
    """Best first by the score (by the domain's ranking metric where it has one), or by a
    physical metric (its domain says which way is better; entries without it last)."""
    if sort == "score":
        return lambda d: (0, -d["score"]["mean"]) if ranking_metric(d["env_id"]) is None else (
            sort_key(ranking_metric(d["env_id"]))(d))

    def key(d):
        metric = (d.get("metrics") or {}).get(sort)
        if metric is None:
            return (1, 0.0)
        sign = 1.0 if get_domain(d["env_id"]).metrics.get(sort) == "lower" else -1.0
        return (0, sign * metric["mean"])

    return key


def published_of(rows: list[dict]) -> tuple[str, list[tuple[str, str]]]:
    """Others' published figures for the track of ``rows`` (:attr:`Domain.published`): a note
    and ``(who, figure)`` rows, or ``("", [])``."""
    domain = get_domain(rows[0]["env_id"])
    if domain.published is None or rows[0]["evaluation"]["protocol"] != OFFICIAL:
        return "", []
    tracked = {k: v for k, v in rows[0]["evaluation"]["options"].items() if k in domain.track_options}
    note, published = domain.published(**tracked)
    return (note, list(published)) if published else ("", [])


def group_entries(entries, sort: str = "score") -> dict:
    """``{(section, env_id, who): [entries best first]}``; section: ``single-agent``,
    ``multi-agent`` or ``variants``; ``who``: the agent, or ``all agents``; best by
    :func:`sort_key`."""
    groups: dict = {}
    for p, d in entries:
        section = d["track"] if d["evaluation"]["protocol"] == OFFICIAL else "variants"
        who = d["agent"] if d["track"] == SINGLE else f"{len(d['agents'])} agents"
        tracked = [f"{k}={v}" for k, v in sorted(d["evaluation"]["options"].items())
                   if k in get_domain(d["env_id"]).track_options]
        if tracked:  # e.g. one track per network
            who = f"{', '.join(tracked)}: {who}"
        groups.setdefault((section, d["env_id"], who), []).append(dict(d, _file=p.name))
    order = {SINGLE: 0, MULTI: 1, "variants": 2}
    for rows in groups.values():
        rows.sort(key=sort_key(sort))
    return dict(sorted(groups.items(), key=lambda kv: (order[kv[0][0]], kv[0][1], kv[0][2])))


def _text_table(rows: list[dict], sort: str = "score") -> list[str]:
    if sort == "score" and ranking_metric(rows[0]["env_id"]) is not None:
        sort = ranking_metric(rows[0]["env_id"])  # that metric's column first, ranked by it
    if sort == "score":
        table = [HEADER] + [_row(d) for d in rows]
    else:
        def metric(d):
            return metric_text((d.get("metrics") or {}).get(sort))

        better = get_domain(rows[0]["env_id"]).metrics.get(sort, "higher")
        table = [[*HEADER[:2], f"{sort} ({better} is better)", *HEADER[2:]]] + [
            [*_row(d)[:2], metric(d), *_row(d)[2:]] for d in rows]
    widths = [max(len(r[i]) for r in table) for i in range(len(table[0]))]
    return ["  " + "  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in table]


def metric_names(entries) -> dict:
    """``{metric: "lower" | "higher"}`` of every domain on the board."""
    names: dict = {}
    for env_id in sorted({d["env_id"] for _, d in entries}):
        names.update(get_domain(env_id).metrics)
    return names


def show(directory=None, sort: str = "score") -> str:
    """A plain-text table of the board (where it is, then per track, domain and agent), best
    first by the score or by a physical metric (``sort``)."""
    board = board_path(directory)
    entries, problems = load_entries(board)
    known = metric_names(entries)
    if sort != "score" and sort not in known:
        raise BadInput(f"--sort {sort!r}: expected 'score' or a metric of the board's domains: "
                         f"{', '.join(f'{k} ({v} is better)' for k, v in known.items()) or 'none'}")
    lines = [f"leaderboard: {board.resolve()}"]
    for p, why in problems:
        lines.append(f"  skipped {console_text(p.name)}: {console_text(why)}")
    lines.append("")
    for (section, env_id, who), rows in group_entries(entries, sort).items():
        lines.append(f"[{section}] {env_id} / {console_text(who)}")
        lines += _text_table(rows, sort)
        lines.append("")
    if not entries:
        lines.append("(no entries yet)")
    archived, _ = load_entries(board, ARCHIVE_SUBDIR)
    if archived:
        lines.append(f"(+ {len(archived)} archived entries whose policies were not kept: see README.md)")
    return "\n".join(lines)


README_HEAD = """# ials_zoo leaderboard

**Score** = mean episodic return on the global simulator over the fixed evaluation seeds
10000..10019 (20 episodes). Single-agent track: one agent runs the policy, every other agent
its scripted controller. Multi-agent track: every agent runs its own policy; an episode's
score is the mean over agents of their returns, and each agent's mean is kept. 95% interval:
BCa bootstrap over the episodes for one training seed, Student-t over the seeds for several.
Protocol: `ials_zoo/evaluation.py`; format and checks: [SCHEMA.md](SCHEMA.md).

**What an entry guarantees.** `ials-zoo leaderboard submit` accepts a result only if it is
valid (schema, finite numbers, every mean and interval recomputed from the returns), follows
the protocol or is listed as a variant below, scores policies that are files of weights plus
JSON (no code: no pickle, no `module:function`) whose sha256 matches, and is not a duplicate
of an entry (same policies, agents and protocol). The policy files are copied into
[`policies/`](policies), so `ials-zoo leaderboard verify results/<file>.json` re-scores any
entry from this folder alone and fails unless every episode's return is re-measured exactly.
A trained entry says what made it (`training.reproduce`); `verify --retrain` runs that training
again and passes only if the policy file comes out bit for bit the same: such entries are marked
**re-trained**. Without that check, an entry's training claims are what its policy files' headers
say (`header-agrees`), or unverified (`external`).

**Wall-clocks.** The seconds a run trained (AIP collection and training included) depend on
the machine and on what else ran on it, 2-4x. Every run now times a fixed reference workload
at its start and at every checkpoint (`ials_zoo/reference_speed.py`); the figure in brackets is
its wall-clock in seconds of the reference machine, which can be compared across entries, and
"timed under load" marks a run whose workload times moved by more than 20% while it trained.
An entry without brackets was trained before runs measured their machine: its seconds compare
only with runs of the same machine and load. `ials-zoo leaderboard compare --wall-clock A B`
compares two entries this way.

Regenerate this page with `ials-zoo leaderboard render` (do not edit it by hand; its write-up
section is copied from [writeup.md](writeup.md)).
"""


def _plot(board: Path, key: tuple, rows: list[dict]) -> str | None:
    curves = [d for d in rows if d["learning_curves"]]
    if not curves:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    section, env_id, who = key
    fig, ax = plt.subplots(figsize=(7, 4.5))
    longest = max(p["wall_clock_seconds"] for d in curves for c in d["learning_curves"] for p in c["points"])
    unit, scale = ("hours", 3600.0) if longest >= 7200 else ("minutes", 60.0)
    kinds: dict = {}
    for d in curves:
        kinds.setdefault((d["algorithm"], _training_label(d), d["training"]["env_steps"]), []).append(d)
    for i, ((algo, sim, steps), ds) in enumerate(kinds.items()):
        color = f"C{i % 10}"
        n = sum(len(d["learning_curves"]) for d in ds)
        label = console_text(f"{algo} on {sim}, {steps:,} steps" + (f" ({n} seeds)" if n > 1 else ""))
        for d in ds:
            for c in d["learning_curves"]:
                xs = [p["wall_clock_seconds"] / scale for p in c["points"]]
                ys = [p["mean"] for p in c["points"]]
                ax.plot(xs, ys, marker="o", ms=2, lw=1, color=color, label=label)
                if n == 1:
                    ax.fill_between(xs, [p["ci_low"] for p in c["points"]], [p["ci_high"] for p in c["points"]],
                                    alpha=0.2, color=color)
                label = None
    for d in rows:
        if d["training"] is None:
            ax.axhline(d["score"]["mean"], ls="--", lw=1, color="grey")
            ax.text(ax.get_xlim()[0], d["score"]["mean"], f" {d['algorithm']}", va="bottom", fontsize=8)
    ax.set_xlabel(f"wall-clock {unit} (training + AIP data collection and training)")
    ax.set_ylabel("GS mean episodic return" + (" (mean over agents)" if section == MULTI else ""))
    ax.set_title(f"{env_id} / {who}")
    return _save_figure(fig, board, key, "")


def _save_figure(fig, board: Path, key: tuple, suffix: str) -> str:
    """Legend, layout, an atomic PNG in ``<board>/plots/``; returns its path in the board."""
    import matplotlib.pyplot as plt

    section, env_id, who = key
    fig.axes[0].legend(fontsize=7)
    fig.tight_layout()
    safe = re.sub(r'[^A-Za-z0-9._-]+', '-', who)
    name = f"{env_id}__{safe}{'__multi' if section == MULTI else ''}{suffix}.png"
    with atomic_path(board / "plots" / name, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return f"plots/{name}"


def _profile_plot(board: Path, key: tuple, rows: list[dict]) -> str | None:
    """Performance profiles (Agarwal et al. 2021): for each entry, the fraction of its
    evaluation episodes, over every training seed, whose score exceeds tau, against tau; the
    references as dashed lines. Drawn where at least one trained entry has several seeds."""
    if not any(d["training"] is not None and len(d["scores"]) > 1 for d in rows):
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    section, env_id, who = key
    fig, ax = plt.subplots(figsize=(7, 4.5))
    everything = np.concatenate([np.asarray(s["returns"], float) for d in rows for s in d["scores"]])
    taus = np.linspace(everything.min(), everything.max(), 200)
    for i, d in enumerate(rows):
        returns = np.concatenate([np.asarray(s["returns"], float) for s in d["scores"]])
        fraction = (returns[None, :] > taus[:, None]).mean(axis=1)
        trained = d["training"] is not None
        label = console_text(f"{d['algorithm']}" + (f" on {_training_label(d)}, {len(d['scores'])} seeds"
                                                     if trained else ""))
        if d["evaluation"].get("deterministic"):
            label += " (deterministic)"
        ax.plot(taus, fraction, lw=1.5 if trained else 1, ls="-" if trained else "--", color=f"C{i % 10}",
                label=label)
    ax.set_xlabel("score tau (episode return" + (", mean over agents)" if section == MULTI else ")"))
    ax.set_ylabel("fraction of episodes (all seeds) scoring above tau")
    ax.set_title(f"{env_id} / {who}: performance profiles")
    return _save_figure(fig, board, key, "__profile")


def _md_table(rows, link: str | None = "results") -> list[str]:
    rank = ranking_metric(rows[0]["env_id"]) if rows else None
    head = HEADER + (["file"] if link else [])
    if rank is not None:  # the ranking metric first, with which way is better
        better = get_domain(rows[0]["env_id"]).metrics[rank]
        head = [*head[:2], f"{rank} [95% CI] ({better} is better)", *head[2:]]
    out = ["| " + " | ".join(head) + " |\n", "|" + "---|" * len(head) + "\n"]
    for d in rows:
        cells = [markdown_cell(c) for c in _row(d)] + ([f"[json]({link}/{d['_file']})"] if link else [])
        if rank is not None:
            cells = [*cells[:2], metric_text((d.get("metrics") or {}).get(rank)), *cells[2:]]
        out.append("| " + " | ".join(cells) + " |\n")
    return out


def markdown_cell(text: str) -> str:
    """User text as one Markdown table cell: no line breaks, ``|`` and HTML escaped, so that no
    entry can add rows, links or markup to the page."""

    flat = console_text(" ".join(str(text).split()))  # no control or direction characters either
    return html.escape(flat, quote=False).replace("|", "\\|").replace("[", "\\[").replace("]", "\\]")


def _sections(board: Path, entries, titles: dict) -> list[str]:
    """Each track's Markdown section: per domain and agents a table, learning curves and
    performance profiles."""
    parts: list[str] = []
    current = None
    for key, rows in group_entries(entries).items():
        section, env_id, who = key
        if section != current:
            parts.append(f"\n## {titles[section]}\n")
            current = section
        parts.append(f"\n### {env_id} / {who}\n\n")
        parts += _md_table(rows)
        note, published = published_of(rows)
        if published:
            parts.append(f"\n*{markdown_cell(note)}:* " + "; ".join(
                f"{markdown_cell(who)} {markdown_cell(figure)}" for who, figure in published) + "\n")
        plot = _plot(board, key, rows)
        if plot:
            parts.append(f"\n![{env_id} {who}]({plot})\n")
        profile = _profile_plot(board, key, rows)
        if profile:
            parts.append(f"\n![{env_id} {who} performance profiles]({profile})\n")
    return parts


def render(directory=None) -> Path:
    """Regenerate ``<board>/README.md`` and ``<board>/plots/*.png``."""
    board = board_path(directory)
    entries, problems = load_entries(board)
    parts = [README_HEAD]
    writeup = board / WRITEUP
    if writeup.exists() or writeup.is_symlink():
        try:
            parts.append("\n" + read_regular_file(writeup, MAX_WRITEUP_BYTES, follow_links=False).decode("utf-8")
                         .strip() + "\n")
        except (ValueError, UnicodeDecodeError) as exc:
            problems.append((writeup, str(exc)))
    if problems:
        # one bad file never hides the rest: it is named here and skipped
        parts.append("\n**Skipped files** (not entries of this board until fixed):\n\n")
        parts += [f"- `{markdown_cell(p.name)}`: {markdown_cell(why)}\n" for p, why in problems]
    titles = {SINGLE: "Single-agent track (one agent learns, the others are scripted)",
              MULTI: "Multi-agent track (every agent learns)",
              "variants": "Protocol variants (other seeds, options or agents: not comparable with the tracks)"}
    import matplotlib

    # entry names are user text: "$...$" must print as written, not go to mathtext (which can
    # fail on it and end the render)
    with matplotlib.rc_context({"text.parse_math": False}):
        parts += _sections(board, entries, titles)
    if not entries:
        parts.append("\n(no entries yet)\n")
    archived, _ = load_entries(board, ARCHIVE_SUBDIR)
    if archived:
        parts.append("\n## Archive (superseded entries, shown apart)\n\n"
                     "Entries of earlier studies, kept as measured then and not entries of the tracks above: "
                     "the first single-agent study's merged 3-seed entries (their policy files were not kept, "
                     "so `verify` cannot check them) and the first DIALS study's multi-agent entries, trained "
                     "with the PPO settings before the ablation of `docs/ablation.md` (their policies are "
                     "in `policies/`: `ials-zoo leaderboard verify archive/<file>.json` re-scores them).\n\n")
        for key, rows in group_entries(archived).items():
            parts.append(f"\n### {key[1]} / {key[2]}\n\n")
            parts += _md_table(rows, link=ARCHIVE_SUBDIR)
    out = board / "README.md"
    atomic_write_text(out, "".join(parts))
    return out


__all__ = ["format_duration", "group_entries", "metric_text", "published_of", "render", "show"]
