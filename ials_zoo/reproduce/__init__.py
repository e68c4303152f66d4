"""``ials-zoo reproduce``: the paper's experiments as a resumable, budgeted study.

* :mod:`ials_zoo.reproduce.plan` -- :class:`Config`, :class:`Job`, :func:`build_plan`
  (experiments ``training`` §5.2-5.3, ``memory`` §5.4, ``dset`` §4.2, ``dials`` §6);
* :mod:`ials_zoo.reproduce.runner` -- :func:`run_jobs`: one subprocess per job, at most
  ``jobs`` at once, finished jobs (marker file present) skipped;
* :mod:`ials_zoo.reproduce.experiments` -- what each job does (AIP training timed here, PPO on
  a domain variant, item lifetimes, off-policy cross-entropy);
* :mod:`ials_zoo.reproduce.report` -- curves, tables, ``reproduction.md``, leaderboard
  submissions, all re-made from the run folders.
"""

from ials_zoo.reproduce.plan import Config, Job, build_plan, describe_plan
from ials_zoo.reproduce.report import submit_results, write_report
from ials_zoo.reproduce.runner import run_jobs


def reproduce(cfg: Config, progress: bool = True, report: bool = True, submit: bool = True) -> dict:
    """Run the study ``cfg`` (skipping finished jobs), then aggregate and submit.

    Returns ``{"jobs": run_jobs' status lists, "report": path, "leaderboard": submissions}``."""

    jobs = build_plan(cfg)
    status = run_jobs(jobs, n_jobs=cfg.jobs, progress=progress, lock_dir=cfg.out)
    out = {"jobs": status, "report": None, "leaderboard": None}
    if submit:
        out["leaderboard"] = submit_results(cfg.out, cfg.leaderboard)
    if report:
        out["report"] = str(write_report(cfg.out, cfg.leaderboard, settings(cfg), cfg.experiments))
    return out


def settings(cfg: Config) -> dict:
    """The settings that shape the numbers (printed in reproduction.md)."""
    budgets = {d: cfg.budget_for(d) for d in cfg.domains}
    return {"budget": budgets, "memory_budget": cfg.memory_budget if cfg.memory_budget is not None else "the domain's budget", "seeds": cfg.seeds, "jobs": cfg.jobs, "net_arch": cfg.net_arch,
            "n_envs": cfg.n_envs, "eval_points": cfg.eval_points, "eval_episodes": cfg.eval_episodes,
            "final_eval_episodes": cfg.final_eval_episodes, "aip_steps": cfg.aip_steps,
            "collect_workers": cfg.collect_workers,
            "aip_epochs": cfg.aip_epochs if cfg.aip_epochs is not None else "default",
            **({"dials_budget_per_agent": {d: cfg.dials_budget_for(d) for d in cfg.domains},
                "dials_workers": cfg.dials_workers} if "dials" in cfg.experiments else {})}


__all__ = ["Config", "Job", "build_plan", "describe_plan", "reproduce", "settings"]
