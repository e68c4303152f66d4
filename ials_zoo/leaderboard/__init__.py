"""Leaderboard results: build, validate, store, show and verify.

* :mod:`~ials_zoo.leaderboard.build` -- results from evaluations (single- and multi-agent
  tracks), merging training seeds;
* :mod:`~ials_zoo.leaderboard.validate` -- the schema (``schema.json``) and every number;
* :mod:`~ials_zoo.leaderboard.store` -- the board folder: entries, policies, ``submit``;
* :mod:`~ials_zoo.leaderboard.render` -- ``show`` and ``README.md`` with plots;
* :mod:`~ials_zoo.leaderboard.verify` -- exact re-scoring of an entry;
* :mod:`~ials_zoo.leaderboard.export` -- the board in other tools' formats (marl-eval).

The format and the guarantees are documented in ``leaderboard/SCHEMA.md``.
"""

from ials_zoo.leaderboard.build import (
    MULTI,
    OFFICIAL,
    SCHEMA_VERSION,
    SINGLE,
    VARIANT,
    hardware_info,
    make_result,
    now_iso,
    overall_score,
    protocol_of,
    reference_result,
    split_env_id,
)
from ials_zoo.leaderboard.export import compare_entries, compare_wall_clock, export_board
from ials_zoo.leaderboard.merge import merge_results
from ials_zoo.leaderboard.render import render, show
from ials_zoo.leaderboard.store import (
    ARCHIVE_SUBDIR,
    POLICIES_SUBDIR,
    RESULTS_SUBDIR,
    board_path,
    entry_name,
    identity,
    load_entries,
    submit,
)
from ials_zoo.leaderboard.validate import (
    MAX_RESULT_BYTES,
    REL_TOL,
    ResultError,
    load_result,
    load_schema,
    validate_result,
    write_result,
)
from ials_zoo.leaderboard.verify import verify

__all__ = [
    "ARCHIVE_SUBDIR",
    "compare_entries",
    "compare_wall_clock",
    "export_board",
    "MAX_RESULT_BYTES",
    "MULTI",
    "OFFICIAL",
    "POLICIES_SUBDIR",
    "REL_TOL",
    "RESULTS_SUBDIR",
    "SCHEMA_VERSION",
    "SINGLE",
    "VARIANT",
    "ResultError",
    "board_path",
    "entry_name",
    "hardware_info",
    "identity",
    "load_entries",
    "load_result",
    "load_schema",
    "make_result",
    "merge_results",
    "now_iso",
    "overall_score",
    "protocol_of",
    "reference_result",
    "render",
    "show",
    "split_env_id",
    "submit",
    "validate_result",
    "verify",
    "write_result",
]
