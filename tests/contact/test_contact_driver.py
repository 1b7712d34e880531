"""The one driver of exact contact (``contact_transfer`` and ``contact_correct``): forked workers give
the serial answer, hold no module state, hand a worker's error to the caller; the solver's rounds
as their documented steps."""

import multiprocessing as mp
import sys

import numpy as np
import pytest

from facebasis.contact import exact
from facebasis.contact.exact import contact_correct, contact_transfer
from facebasis.contact.solver import ContactShape, ContactSolver
from facebasis.errors import SolverError
from facebasis.geometry.transfer import DeformationTransfer
from conftest import stretched, two_sheets

needs_fork = pytest.mark.skipif(sys.platform != "linux" or "fork" not in mp.get_all_start_methods(),
                                reason="the worker processes need fork")


def _two_shapes():
    """The two sheets with a second shape pushing the top sheet down harder (two shapes to share out)."""
    rig = two_sheets()
    deltas = rig.deltas.copy()
    deltas[1] = 1.2 * deltas[0]
    return type(rig)(rig.neutral, rig.faces, ("push", "harder"), deltas)


@needs_fork
def test_forked_workers_give_the_serial_answer_and_leave_no_module_state():
    rig = _two_shapes()
    target = stretched(rig.neutral)
    serial = contact_transfer(rig, target, reach=0.5, workers=1)
    forked = contact_transfer(rig, target, reach=0.5, workers=2)
    assert serial.seconds["workers"] == 1 and forked.seconds["workers"] == 2
    assert np.array_equal(serial.rig.deltas, forked.rig.deltas)
    strip = [dict(vars(s), seconds=0.0) for s in serial.shapes]
    assert strip == [dict(vars(s), seconds=0.0) for s in forked.shapes]
    assert serial.ok and all(s.plain_new_pairs > 0 for s in serial.shapes)
    # nothing of the run is left in the module (the workers inherit the solver through the fork)
    assert not any(isinstance(v, ContactSolver) for v in vars(exact).values())
    # contact_correct goes through the same driver: the plain transfer corrected gives the same shapes
    again = contact_correct(serial.plain, rig, reach=0.5, stiffness=0.0, max_iterations=40, workers=2)
    assert np.array_equal(again.rig.deltas, serial.rig.deltas)


@needs_fork
def test_an_error_in_a_worker_reaches_the_caller(monkeypatch):
    def broken(solver, job):
        raise SolverError(f"contact ({job[0]}): expected the separation QP solved, found a broken worker")

    monkeypatch.setattr(exact, "_correct_job", broken)   # inherited by the forked workers
    rig = _two_shapes()
    with pytest.raises(SolverError, match=r"contact \((push|harder)\): .*found a broken worker"):
        contact_transfer(rig, stretched(rig.neutral), reach=0.5, workers=2)


def test_excluded_shapes_are_reported_and_left_plain():
    rig = _two_shapes()
    res = contact_transfer(rig, stretched(rig.neutral), reach=0.5, exclude=["harder"], workers=1)
    assert res.shapes[1] == ContactShape("harder", excluded=True)
    assert np.array_equal(res.rig.deltas[1], res.plain.deltas[1])
    assert res.shapes[0].plain_new_pairs > 0 and res.shapes[0].new_pairs_left == 0


def test_the_rounds_report_their_steps():
    """``_correct`` with no round constrains nothing and reports the plain solution's pairs as left;
    one round constrains exactly the plain pairs (step 2), moves only the region around them (step 3)
    and counts its ADMM iterations; enough rounds end clean (step 4)."""
    rig = two_sheets()
    dt = DeformationTransfer(rig, stretched(rig.neutral))
    plain = dt.transfer()
    solver = ContactSolver(dt, reach=0.5, polish=0)
    d0, rep0, left0 = solver._correct("push", plain.deltas[0], rig.deltas[0], solver.L, 0)
    assert rep0.iterations == 0 and rep0.constrained_pairs == 0 and len(left0) == rep0.plain_new_pairs > 0
    assert np.array_equal(d0, plain.deltas[0])
    d1, rep1, _ = solver._correct("push", plain.deltas[0], rig.deltas[0], solver.L, 1)
    assert rep1.iterations == 1 and rep1.constrained_pairs == rep1.plain_new_pairs and rep1.solver_iterations > 0
    moved = np.flatnonzero(np.abs(d1 - plain.deltas[0]).max(1) > 0)
    assert 0 < len(moved) <= rep1.moved < rig.n_vertices
    d, rep, left = solver._correct("push", plain.deltas[0], rig.deltas[0], solver.L, 40)
    assert len(left) == rep.new_pairs_left == 0 and rep.iterations > 1 and rep.min_distance > 0
