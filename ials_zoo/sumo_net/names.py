"""The names of ``sumo_net_v0`` and its options, apart from the env (the domain record reads
them without importing the env: ``import ials_zoo`` stays fast)."""

ENV_ID = "sumo_net_v0"
SCENARIO_OPTIONS = ("net", "sumocfg", "net_file", "route_files", "begin", "end", "decision_seconds", "yellow_seconds",
                    "max_cycles")
DEFAULT_NET = "cologne8"
OPTIONS = (*SCENARIO_OPTIONS, "learners", "max_distance", "observation", "reward", "backend", "fresh_process",
           "region_data", "render_mode")
# what a board entry's evaluation may set: no file paths (a result file never makes us read a
# path it names), so networks of your own are scored off the board
BOARD_OPTIONS = ("net", "begin", "end", "decision_seconds", "yellow_seconds", "max_cycles", "max_distance",
                 "observation", "reward")

__all__ = ["BOARD_OPTIONS", "DEFAULT_NET", "ENV_ID", "OPTIONS", "SCENARIO_OPTIONS"]
