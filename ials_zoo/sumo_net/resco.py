"""RESCO's published delays (s), the reference our controllers are checked against.

From RESCO's own result files (``resco_benchmark/utils/avg_timeLoss.py``, Pi-Star-Lab/RESCO at
fc65e91), reduced with its ``utils/graph.py``: a rule-based controller's figure is the mean over
its episodes (the median beside it: gridlocked episodes give heavy tails, as RESCO runs without
teleports); a learner's is the best *training* episode of the trial-mean curve. RESCO's figure
legend calls the MAXWAVE series "Max Pressure" and the MAXPRESSURE series "Greedy" while its
code maps MAXWAVE to "Greedy": compare a controller with both columns.
"""

from __future__ import annotations

# map -> (mean, median) per RESCO key; None where RESCO ran none
RULE_BASED = {
    "grid4x4": {"FIXED": None, "MAXWAVE": (34.32, 34.45), "MAXPRESSURE": (52.55, 52.53)},
    "arterial4x4": {"FIXED": None, "MAXWAVE": (820.81, 710.86), "MAXPRESSURE": (952.75, 967.95)},
    "ingolstadt1": {"FIXED": (39.4, 39.47), "MAXWAVE": (28.32, 27.99), "MAXPRESSURE": (23.62, 23.61)},
    "ingolstadt7": {"FIXED": (91.31, 91.45), "MAXWAVE": (80.56, 80.31), "MAXPRESSURE": (46.82, 46.41)},
    "ingolstadt21": {"FIXED": (133.1, 130.37), "MAXWAVE": (76.32, 69.61), "MAXPRESSURE": (136.72, 115.61)},
    "cologne1": {"FIXED": (56.61, 56.85), "MAXWAVE": (27.81, 27.94), "MAXPRESSURE": (65.85, 31.09)},
    "cologne3": {"FIXED": (46.35, 39.04), "MAXWAVE": (90.67, 21.95), "MAXPRESSURE": (162.28, 28.05)},
    "cologne8": {"FIXED": (63.77, 64.21), "MAXWAVE": (21.87, 21.85), "MAXPRESSURE": (47.73, 29.71)},
}

# map -> best training episode's delay of RESCO's learners (IDQN and MPLight: 100 episodes, IPPO
# and FMA2C: 1,400); RESCO's MPLight series is empty on ingolstadt1
LEARNED = {
    "grid4x4": {"IDQN": 32.95, "IPPO": 44.0, "MPLight": 46.91, "FMA2C": 99.77},
    "arterial4x4": {"IDQN": 1168.32, "IPPO": 686.62, "MPLight": 837.75, "FMA2C": 654.13},
    "ingolstadt1": {"IDQN": 21.48, "IPPO": 20.9, "FMA2C": 27.0},
    "ingolstadt7": {"IDQN": 31.19, "IPPO": 31.68, "MPLight": 48.21, "FMA2C": 51.39},
    "ingolstadt21": {"IDQN": 59.64, "IPPO": 93.11, "MPLight": 78.16, "FMA2C": 90.29},
    "cologne1": {"IDQN": 26.05, "IPPO": 43.24, "MPLight": 28.74, "FMA2C": 30.79},
    "cologne3": {"IDQN": 23.99, "IPPO": 24.03, "MPLight": 83.65, "FMA2C": 26.86},
    "cologne8": {"IDQN": 22.06, "IPPO": 21.62, "MPLight": 60.42, "FMA2C": 33.88},
}

PUBLISHED_NOTE = ("RESCO's published delays (Ault & Sharon 2021): SUMO 1.9 and RESCO's own map files, not "
                  "re-measured here; a learner's is its best training episode, a rule's the mean over its episodes "
                  "(median in brackets)")


def published_rows(net: str) -> list[tuple[str, str]]:
    """RESCO's figures for map ``net`` (none for another network): ``(who, delay)``."""
    if net not in LEARNED:
        return []
    rows = [(f"RESCO {k}", f"{v:.2f}") for k, v in LEARNED[net].items()]
    return rows + [(f"RESCO {k}", f"{x[0]:.2f} ({x[1]:.2f})") for k, x in RULE_BASED[net].items() if x is not None]


# our controller -> the RESCO keys it is compared with
COMPARED = {"fixed": ("FIXED",), "plain_sumo": ("FIXED",), "greedy": ("MAXWAVE", "MAXPRESSURE"),
            "max_pressure": ("MAXPRESSURE", "MAXWAVE")}

# maps whose files in the sumo-rl wheel differ from RESCO's in what is simulated
FILE_DIFFERENCES = {
    "ingolstadt7": "one junction lacks a 25 s green (sumo-rl's file)",
    "ingolstadt21": "one junction lacks a 25 s green (sumo-rl's file)",
    "grid4x4": "one route file for every episode (RESCO: one per episode)",
    "arterial4x4": "one route file for every episode (RESCO: one per episode)",
}

__all__ = ["COMPARED", "FILE_DIFFERENCES", "LEARNED", "PUBLISHED_NOTE", "RULE_BASED", "published_rows"]
