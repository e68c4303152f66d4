"""An episode's metrics from SUMO's tripinfo output, computed as RESCO computes them.

RESCO (``resco_benchmark/utils/readXML.py``) reads ``tripinfo_<episode>.xml``, written with
``--tripinfo-output.write-unfinished`` (vehicles still driving at the end are included):

* **delay**: the mean over tripinfo records of ``timeLoss + departDelay``, plus, for every
  ``<vehicle>`` of the route file scheduled after the scheduled departure of the vehicle that
  departed last (and before the episode's end), a record of ``end - scheduled depart`` (it
  never departed). RESCO's loop reads
  only ``<vehicle>`` elements, so route files of ``<trip>`` elements (cologne1/8, the Ingolstadt
  maps) never get that penalty. ``delay`` is RESCO's figure; ``delay_all`` charges never-departed
  ``<trip>`` entries as well (``<flow>`` entries are not counted by either).
* **trip_time**, **waiting_time**: the mean ``duration`` and ``waitingTime`` of the records.
* **throughput**: vehicles that arrived; **vehicles**: tripinfo records.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET

import numpy as np

from ials_zoo.errors import BadInput

MAX_TRIPINFO_BYTES = 1 << 30
MAX_ROUTE_BYTES = 256 << 20


def iter_elements(path: str, max_bytes: int, tag: str | None = None):
    """The elements of the XML file at ``path`` (no larger than ``max_bytes``) as they end,
    those named ``tag`` only if given; a broken file is a :class:`BadInput` naming it."""
    size = os.path.getsize(path)
    if size > max_bytes:
        raise BadInput(f"{path}: {size / 2**20:.0f} MiB is more than {max_bytes >> 20} MiB")
    try:
        for _, el in ET.iterparse(path, events=("end",)):
            if tag is None or el.tag == tag:
                yield el
    except ET.ParseError as exc:  # a truncated or broken file: named, not a bare ParseError
        raise BadInput(f"{path} is not a whole XML file ({exc}); SUMO would run on part of it") from None


def read_tripinfo(path: str) -> dict[str, np.ndarray]:
    """The tripinfo records as arrays (``id`` a list of str)."""
    keys = ("depart", "departDelay", "timeLoss", "duration", "waitingTime", "arrival")
    rows, ids = [], []
    for el in iter_elements(path, MAX_TRIPINFO_BYTES, "tripinfo"):
        rows.append([float(el.get(k, "nan")) for k in keys])
        ids.append(el.get("id"))
        el.clear()
    table = np.array(rows, np.float64).reshape(-1, len(keys))
    return {"id": ids, **{k: table[:, i] for i, k in enumerate(keys)}}


def scheduled_departures(route_files) -> tuple[dict[str, float], list[tuple[str, float]]]:
    """``id -> scheduled depart`` of every ``<vehicle>``/``<trip>``, and ``(tag, depart)`` in file order."""
    depart, entries = {}, []
    for path in route_files:
        for el in iter_elements(path, MAX_ROUTE_BYTES):
            if el.tag in ("vehicle", "trip") and el.get("depart") is not None:
                try:
                    t = float(el.get("depart"))
                except ValueError:
                    continue  # "triggered", "now": no scheduled time
                depart[el.get("id")] = t
                entries.append((el.tag, t))
            if el.tag not in ("route", "edge"):
                el.clear()
    return depart, entries


def resco_delay(trips: dict, route_files, end: float, tags=("vehicle",), schedule=None) -> float:
    """RESCO's average delay (see the module docstring); ``tags`` are the route entries whose
    never-departed vehicles are charged ``end - depart`` (RESCO: ``<vehicle>`` only);
    ``schedule``: ``scheduled_departures(route_files)`` if already read."""
    total = float(np.sum(trips["timeLoss"] + trips["departDelay"]))
    count = len(trips["id"])
    if count == 0:
        return float("nan")
    departed = trips["depart"] >= 0
    last_id = trips["id"][int(np.argmax(np.where(departed, trips["depart"], -np.inf)))]
    scheduled, entries = schedule if schedule is not None else scheduled_departures(route_files)
    last_scheduled = scheduled.get(last_id)
    if last_scheduled is not None:
        # scheduled before the end: an episode shorter than its route file (max_cycles) does not
        # charge the vehicles it never had time for (RESCO's episodes cover every departure)
        never = [t for tag, t in entries if tag in tags and last_scheduled < t < end]
        total += float(np.sum(end - np.asarray(never, np.float64)))
        count += len(never)
    return total / count


def episode_metrics(tripinfo: str, route_files, end: float, schedule=None) -> dict[str, float]:
    """delay (RESCO's), delay_all, trip_time, waiting_time, throughput, vehicles; ``schedule``:
    ``scheduled_departures(route_files)``, if the caller keeps it across episodes."""
    trips = read_tripinfo(tripinfo)
    schedule = schedule if schedule is not None else scheduled_departures(route_files)
    return {
        "delay": resco_delay(trips, route_files, end, schedule=schedule),
        "delay_all": resco_delay(trips, route_files, end, tags=("vehicle", "trip"), schedule=schedule),
        "trip_time": float(np.mean(trips["duration"])) if len(trips["id"]) else float("nan"),
        "waiting_time": float(np.mean(trips["waitingTime"])) if len(trips["id"]) else float("nan"),
        "throughput": float(np.sum(trips["arrival"] >= 0)),
        "vehicles": float(len(trips["id"])),
    }


__all__ = ["episode_metrics", "iter_elements", "read_tripinfo", "resco_delay", "scheduled_departures"]
