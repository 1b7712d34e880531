"""What ``facebasis rig`` and ``rig --resume`` share: the cross-validation flags given, the progress
lines of the alternations and the warnings after a run."""

from __future__ import annotations

import sys


def cv_flags_given(args) -> list[str]:
    """The cross-validation flags given (they only mean something with ``--alpha auto`` on a fresh run)."""
    return [flag for flag, v in (("--cv-folds", args.cv_folds), ("--cv-grid", args.cv_grid or None),
                                 ("--cv-candidates", args.cv_candidates)) if v is not None]


def progress(rec, total):
    flag = "" if rec.ipopt_success else f"  [IPOPT: {rec.ipopt_status}]"
    ipopt = f"IPOPT {rec.ipopt_iterations} it" if rec.ipopt_iterations else "certified"
    print(f"  iteration {rec.iteration}/{total}: alpha {rec.alpha:.3g} lambda {rec.lam:.3g} "
          f"E_fit {rec.e_fit:.4g} E_reg {rec.e_reg:.4g} weight objective {rec.weight_objective:.6g} "
          f"({ipopt}, {rec.basis_seconds + rec.weight_seconds:.2f} s){flag}", flush=True)


def cv_progress(fold, alpha, error):
    print(f"  cross-validation fold {fold + 1}: alpha {alpha:g} held-out error {error:.4f}", flush=True)


def warnings(result, options, names):
    for h in result.history:
        if not h.ipopt_success:
            print(f"warning: IPOPT returned {h.ipopt_status} at iteration {h.iteration}; its answer was replaced "
                  "by the certified optimum (branch and bound)", file=sys.stderr)
    for name in result.missing:
        print(f"warning: training expression {name} keeps a relative residual of "
              f"{result.residuals[names.index(name)]:.3f} > {options.missing_threshold}: the template "
              "may lack a shape it needs (missing expression)", file=sys.stderr)
