"""Serialising results (history, options) to plain JSON for reports."""

from __future__ import annotations

import dataclasses


def history_to_json(result, options, problem) -> dict:
    """The per-iteration history of a generation run with its options."""
    opts = dataclasses.asdict(options)
    return {
        "options": opts,
        "exclusive": [list(p) for p in problem.exclusive],
        "examples": list(problem.example_names),
        "shapes": list(problem.template.names),
        "precompute_seconds": result.precompute_seconds,
        "seconds": result.seconds,
        "all_ipopt_succeeded": result.all_ipopt_succeeded,
        "iterations": [dataclasses.asdict(h) for h in result.history],
    }
