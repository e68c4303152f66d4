"""The board as one web page (``<board>/index.html``, written by ``ials-zoo leaderboard render``).

Per track, domain and agents (and per map where a domain has tracks of its own), a table that
sorts by any column when its header is clicked (best first on the first click: lower first for
lower-is-better metrics, which their header says), the official entries apart from the protocol
variants and from the archive; and the learning curves of the trained entries against
environment steps and against wall-clock, each seed's 95% interval as a band, a point's numbers
on hover, an entry shown or hidden from its legend box.

The page is self-contained: its style sheet and script are inline, the curves are inline SVG, and
nothing is fetched from elsewhere, so it opens from the file system and from any static host. An
entry links to its JSON, its policy files and the command that verifies it; ``link_base`` puts
those links elsewhere (the documentation site links to the repository). Every string of an entry
is HTML-escaped.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

import ials_zoo
from ials_zoo.core.domains import get_domain
from ials_zoo.leaderboard.build import MULTI, SINGLE
from ials_zoo.leaderboard.render import (
    _iqm,
    _total_seconds,
    _training_label,
    console_text,
    group_entries,
    metric_text,
    published_of,
    wall_clock_text,
)
from ials_zoo.leaderboard.store import ARCHIVE_SUBDIR, board_path, load_entries
from ials_zoo.utils import atomic_write_text

PAGE = "index.html"
BOARD_POLICY = re.compile(r"policies/[0-9a-f]{64}\.safetensors")
"""The only policy paths linked: the board's own copies."""
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
          "#17becf")

STYLE = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:2em auto;max-width:1400px;padding:0 1em;
color:#222}
h1{font-size:1.6em}h2{margin-top:2em;border-bottom:1px solid #ccc}h3{margin-top:1.6em}
table.board{border-collapse:collapse;font-size:.85em;margin:.6em 0;width:100%}
table.board th,table.board td{border:1px solid #ddd;padding:.25em .4em;text-align:left;vertical-align:top;
overflow-wrap:anywhere}
table.board details code{display:block;white-space:normal;overflow-wrap:anywhere;margin-top:.2em}
table.board th{background:#f4f4f4;cursor:pointer;user-select:none}
table.board th.sorted-asc::after{content:" \\25B2"}table.board th.sorted-desc::after{content:" \\25BC"}
td.num{text-align:right;font-variant-numeric:tabular-nums}code{font-size:.92em}
.curves{display:flex;flex-wrap:wrap;gap:1em}.legend label{margin-right:1em;font-size:.88em;white-space:nowrap}
svg text{font-size:11px;fill:#333}.note{color:#555;font-size:.9em}
svg polygon,svg polyline{pointer-events:none}
nav.toc{font-size:.92em;columns:2;margin:1em 0}nav.toc ul{margin:.2em 0 .6em}nav.toc p{margin:.2em 0;font-weight:600}
"""

SCRIPT = """
function sortTable(th){
  const table=th.closest('table'),body=table.tBodies[0],col=th.cellIndex;
  const better=th.dataset.better||'higher';
  let asc=th.classList.contains('sorted-desc')||(!th.classList.contains('sorted-asc')&&better==='lower');
  if(th.classList.contains('sorted-asc'))asc=false;
  for(const h of table.tHead.rows[0].cells)h.classList.remove('sorted-asc','sorted-desc');
  th.classList.add(asc?'sorted-asc':'sorted-desc');
  const key=r=>{const c=r.cells[col];const v=c.dataset.sort;return v===undefined?c.textContent:v};
  const rows=Array.from(body.rows);
  rows.sort((a,b)=>{let x=key(a),y=key(b);const nx=parseFloat(x),ny=parseFloat(y);
    if(x===''&&y!=='')return 1;if(y===''&&x!=='')return -1;
    const cmp=(!isNaN(nx)&&!isNaN(ny))?nx-ny:String(x).localeCompare(String(y));return asc?cmp:-cmp});
  for(const r of rows)body.appendChild(r);
}
document.querySelectorAll('table.board th').forEach(th=>th.addEventListener('click',()=>sortTable(th)));
document.querySelectorAll('.legend input').forEach(box=>box.addEventListener('change',()=>{
  document.querySelectorAll('[data-series="'+box.dataset.series+'"]').forEach(
    el=>{el.style.display=box.checked?'':'none'})}));
"""


def _e(text) -> str:
    """User text for the page: HTML escaped, and every character that is not printable (NUL, ESC,
    BEL, U+2028, U+202E that would show a name reversed) written as its escape, as ``show`` does."""
    return html.escape(console_text(text), quote=True)


def _cell(text: str, sort=None, numeric: bool = False) -> str:
    attrs = (f' data-sort="{_e(sort)}"' if sort is not None else "") + (' class="num"' if numeric else "")
    return f"<td{attrs}>{text}</td>"


def _links(d: dict, folder: str, link_base: str) -> str:
    """The entry's JSON, its policy files and the command that verifies it."""
    name = d["_file"]
    parts = [f'<a href="{_e(link_base + folder + "/" + name)}">json</a>']
    for i, s in enumerate(d["scores"]):
        name_i = f"policy{'' if len(d['scores']) == 1 else f' {i}'}"
        if s.get("policy_file") and BOARD_POLICY.fullmatch(s["policy_file"]):
            parts.append(f'<a href="{_e(link_base + s["policy_file"])}">{name_i}</a>')
        elif s.get("policy_file"):  # not a board file: shown, never linked (no javascript: or other hosts)
            parts.append(f"{name_i}: <code>{_e(s['policy_file'])}</code>")
    checks = [f"ials-zoo leaderboard verify {folder}/{name}"]
    if (d.get("training") or {}).get("reproduce"):
        checks.append(f"ials-zoo leaderboard verify --retrain {folder}/{name}")
    return (" ".join(parts) + "<details><summary>verify</summary>"
            + "".join(f"<code>{_e(c)}</code>" for c in checks) + "</details>")


def _label(d: dict) -> str:
    label = d["algorithm"] + (" (deterministic)" if d["evaluation"].get("deterministic") else "")
    if d["policy"]["kind"] == "rule":
        label += " (rule)"
    tags = []
    if d.get("provenance") == "external":
        tags.append("external: training claims unverified")
    if d.get("retrained"):
        tags.append("re-trained")
    return _e(label) + "".join(f" <em>[{_e(t)}]</em>" for t in tags)


def _table(rows: list[dict], folder: str, link_base: str) -> str:
    env_id = rows[0]["env_id"]
    metrics = get_domain(env_id).metrics
    names = [m for m in metrics if any(m in (d.get("metrics") or {}) for d in rows)]
    head = ['<th data-better="higher">policy / algorithm</th>', "<th>trained on</th>",
            '<th data-better="higher">GS score</th>', '<th data-better="higher" title="sorts by the interval\'s lower end">95% CI</th>',
            '<th data-better="higher">IQM [95% CI]</th>',
            "<th>seeds</th>", "<th>episodes</th>", "<th>env steps</th>", '<th data-better="lower">wall-clock (+AIP) [on the reference machine]</th>']
    head += [f'<th data-better="{metrics[m]}">{_e(m)} ({metrics[m]} is better)</th>' for m in names]
    head += ["<th>date</th>", "<th>files and checks</th>"]
    body = []
    for d in rows:
        s, t = d["score"], d["training"]
        total, iqm = _total_seconds(d), _iqm(d)
        cells = [_cell(_label(d)), _cell(_e(_training_label(d))),
                 _cell(f"{s['mean']:.2f}", s["mean"], True),
                 _cell(f"[{s['ci_low']:.2f}, {s['ci_high']:.2f}]", s["ci_low"], True),
                 _cell(_e(iqm), iqm.split()[0] if iqm != "-" else "", True), _cell(str(len(d["scores"])) if t else "-", len(d["scores"]) if t else "", True),
                 _cell(str(d["evaluation"]["episodes"]), d["evaluation"]["episodes"], True),
                 _cell(f"{t['env_steps']:,}" if t else "-", t["env_steps"] if t else "", True),
                 _cell(_e(wall_clock_text(d)), "" if total is None else total, True)]
        for m in names:
            v = (d.get("metrics") or {}).get(m)
            cells.append(_cell(_e(metric_text(v)), "" if v is None else v["mean"], True))
        cells += [_cell(_e(d["created"][:10])), _cell(_links(d, folder, link_base))]
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (f'<table class="board"><thead><tr>{"".join(head)}</tr></thead><tbody>{"".join(body)}</tbody></table>')


def _tick(value: float) -> str:
    """An axis label short enough for its place: 3 significant digits, k and M for thousands
    and millions (``3.58k``, not ``3.58e+03``)."""
    for size, unit in ((1e6, "M"), (1e3, "k")):
        if abs(value) >= size:
            return f"{value / size:.3g}{unit}"
    return f"{value:.3g}"


def _svg(curves: list[tuple[str, dict]], x_key: str, x_label: str, y_label: str, width=540, height=320) -> str:
    """One panel: each entry's seeds as lines over their 95% bands, a circle per point whose
    title is its numbers and whose data attributes are the result's own values."""
    points = [p for _, c in curves for p in c["points"]]
    xs = [float(p[x_key]) for p in points]
    ys = [float(v) for p in points for v in (p["ci_low"], p["ci_high"], p["mean"])]
    x0, x1 = min(xs), max(xs) if max(xs) > min(xs) else min(xs) + 1.0
    y0, y1 = min(ys), max(ys) if max(ys) > min(ys) else min(ys) + 1.0
    left, right, top, bottom = 56, 24, 12, 40

    def X(v):
        return left + (float(v) - x0) / (x1 - x0) * (width - left - right)

    def Y(v):
        return top + (1.0 - (float(v) - y0) / (y1 - y0)) * (height - top - bottom)

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" role="img" '
           f'aria-label="{_e(y_label)} against {_e(x_label)}">',
           f'<rect x="{left}" y="{top}" width="{width - left - right}" height="{height - top - bottom}" fill="none" '
           'stroke="#999"/>']
    for i in range(5):
        yv, xv = y0 + (y1 - y0) * i / 4, x0 + (x1 - x0) * i / 4
        out.append(f'<text x="{left - 4}" y="{Y(yv) + 4:.1f}" text-anchor="end">{_tick(yv)}</text>')
        anchor = "end" if i == 4 else "start" if i == 0 else "middle"  # the end ticks stay inside the panel
        out.append(f'<text x="{X(xv):.1f}" y="{height - bottom + 14}" text-anchor="{anchor}">{_tick(xv)}</text>')
    out.append(f'<text x="{(left + width - right) / 2}" y="{height - 6}" text-anchor="middle">{_e(x_label)}</text>')
    out.append(f'<text x="12" y="{(top + height - bottom) / 2}" transform="rotate(-90 12 {(top + height - bottom) / 2})" '
               f'text-anchor="middle">{_e(y_label)}</text>')
    for series, curve in curves:
        color = COLORS[int(series.rsplit("-", 1)[1]) % len(COLORS)]
        pts = sorted(curve["points"], key=lambda p: float(p[x_key]))
        band = [f"{X(p[x_key]):.1f},{Y(p['ci_high']):.1f}" for p in pts] + \
               [f"{X(p[x_key]):.1f},{Y(p['ci_low']):.1f}" for p in reversed(pts)]
        line = " ".join(f"{X(p[x_key]):.1f},{Y(p['mean']):.1f}" for p in pts)
        out.append(f'<g data-series="{series}"><polygon points="{" ".join(band)}" fill="{color}" fill-opacity="0.15" '
                   f'stroke="none"/><polyline points="{line}" fill="none" stroke="{color}" stroke-width="1.5"/>')
        for p in pts:
            tip = (f"{curve['_entry']}, seed {curve.get('seed')}: {float(p[x_key]):,.6g} {x_label}: "
                   f"{p['mean']:.4g} [{p['ci_low']:.4g}, {p['ci_high']:.4g}]")
            out.append(f'<circle class="point" cx="{X(p[x_key]):.1f}" cy="{Y(p["mean"]):.1f}" r="3" fill="{color}" '
                       f'data-x="{_e(repr(float(p[x_key])))}" data-mean="{_e(repr(float(p["mean"])))}" '
                       f'data-entry="{_e(curve["_entry"])}" data-seed="{_e(curve.get("seed"))}">'
                       f"<title>{_e(tip)}</title></circle>")
        out.append("</g>")
    out.append("</svg>")
    return "".join(out)


def _curves(rows: list[dict], group: int) -> str:
    """The trained entries' learning curves against steps and against wall-clock, with a legend
    of boxes that show or hide an entry."""
    trained = [(i, d) for i, d in enumerate(rows) if d["learning_curves"]]
    if not trained:
        return ""
    curves, legend = [], []
    for i, d in trained:
        series = f"g{group}-{i}"
        name = f"{d['algorithm']} on {_training_label(d)} ({d['_file']})"
        color = COLORS[i % len(COLORS)]
        legend.append(f'<label><input type="checkbox" checked data-series="{series}"> '
                      f'<span style="color:{color}">&#9632;</span> {_e(name)}</label>')
        curves += [(series, dict(c, _entry=d["_file"])) for c in d["learning_curves"] if c["points"]]
    if not curves:  # entries whose curves hold no point
        return ""
    ylabel = "GS mean return" + (" (mean over agents)" if rows[0]["track"] == MULTI else "")
    panels = [_svg(curves, "env_steps", "env steps per agent", ylabel),
              _svg(curves, "wall_clock_seconds", "wall-clock seconds (training + AIP)", ylabel)]
    return (f'<div class="legend">{"".join(legend)}</div><div class="curves">{"".join(panels)}</div>'
            '<p class="note">Each line is one training seed, its band that evaluation\'s 95% interval; hover a '
            "point for its numbers; a box shows or hides an entry.</p>")


def _sections(groups: dict, folder: str, link_base: str, titles: dict, start: int = 0) -> list[str]:
    parts, current = [], None
    for n, ((section, env_id, who), rows) in enumerate(groups.items(), start):
        if section != current:
            parts.append(f"<h2>{_e(titles.get(section, section))}</h2>")
            current = section
        parts.append(f'<h3 id="{_anchor(n)}">{_e(env_id)} / {_e(who)}</h3>')
        rank = get_domain(env_id).score_metric
        if rank is not None:
            parts.append(f'<p class="note">Ranked by {_e(rank)}, {_e(get_domain(env_id).metrics[rank])} is better.</p>')
        parts.append(_table(rows, folder, link_base))
        note, published = published_of(rows)
        if published:
            parts.append(f'<p class="note">{_e(note)}: ' + "; ".join(f"{_e(who)} {_e(figure)}" for who, figure in published)
                         + "</p>")
        parts.append(_curves(rows, n))
    return parts


def _anchor(n: int) -> str:
    return f"table-{n}"


def _toc(groups: dict, titles: dict) -> str:
    """The page's contents: first the tables of a domain with a track per network (real city
    maps are what most traffic users look for), then every section's tables in page order."""
    keys = list(groups)
    networks = [n for n, (_, env_id, who) in enumerate(keys) if get_domain(env_id).track_options]
    sections: dict = {}
    for n, (section, env_id, who) in enumerate(keys):
        sections.setdefault(titles.get(section, section), []).append(n)
    blocks = ([("Networks and maps (a table per network)", networks)] if networks else []) + list(sections.items())

    def item(n):
        section, env_id, who = keys[n]
        where = "" if section in (SINGLE, MULTI) else f" ({_e(section)})"
        return f'<li><a href="#{_anchor(n)}">{_e(env_id)} / {_e(who)}</a>{where}</li>'

    return ('<nav class="toc" aria-label="contents">'
            + "".join(f"<p>{_e(title)}</p><ul>{''.join(item(n) for n in ns)}</ul>" for title, ns in blocks)
            + "</nav>")


TITLES = {SINGLE: "Single-agent track (one agent learns, the others are scripted)",
          MULTI: "Multi-agent track (every agent learns)",
          "variants": "Protocol variants (other seeds, options or agents: not comparable with the tracks)"}


def render_site(directory=None, out: str | Path | None = None, link_base: str = "") -> Path:
    """Write the board's web page (module docstring) to ``out`` (default ``<board>/index.html``);
    ``link_base`` is put before every link to an entry's files. Returns the page's path."""
    board = board_path(directory)
    entries, problems = load_entries(board)
    archived, _ = load_entries(board, ARCHIVE_SUBDIR)
    groups = group_entries(entries)
    parts = [f"<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>ials_zoo leaderboard</title>"
             f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><style>{STYLE}</style></head><body>",
             "<h1>ials_zoo leaderboard</h1>",
             '<p>Score: the mean episodic return on the global simulator over the fixed evaluation seeds 10000..10019 '
             "(20 episodes; on the multi-agent track the mean over agents); 95% interval over the episodes for one "
             "training seed, over the seeds for several. Every entry was re-measured on the GS before it was "
             "accepted; <em>re-trained</em> entries were trained again from their recorded command, bit for bit. "
             "Click a column's header to sort by it.</p>",
             f'<p class="note">Generated by <code>ials-zoo leaderboard render</code>, ials_zoo {_e(ials_zoo.__version__)}, '
             f"from {len(entries)} entries.</p>"]
    if problems:
        parts.append("<p><strong>Skipped files</strong>: " + "; ".join(f"<code>{_e(p.name)}</code>: {_e(w)}"
                                                                         for p, w in problems) + "</p>")
    parts.append(_toc(groups, TITLES))
    parts += _sections(groups, "results", link_base, TITLES)
    if archived:
        parts += _sections({("archive", k[1], k[2]): v for k, v in group_entries(archived).items()}, ARCHIVE_SUBDIR,
                           link_base, {"archive": "Archive (superseded entries of earlier studies, shown apart)"},
                           start=len(groups))
    parts.append(f"<script>{SCRIPT}</script></body></html>\n")
    path = Path(out) if out is not None else board / PAGE
    atomic_write_text(path, "".join(parts))
    return path


def entry_points(page: str) -> list[dict]:
    """The curve points of a written page, as its circles' data attributes hold them."""
    found = re.findall(r'data-x="([^"]+)" data-mean="([^"]+)" data-entry="([^"]+)" data-seed="([^"]*)"', page)
    return [{"x": float(x), "mean": float(m), "entry": html.unescape(e), "seed": html.unescape(sd)}
            for x, m, e, sd in found]


__all__ = ["PAGE", "entry_points", "render_site"]
