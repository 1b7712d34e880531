"""The benchmarks' baselines run the former model: ``before`` is the defaults before issue 23, the
landmark noise in rig units included (``noise_model="rig"``; the default is now "pixels")."""

import inspect

from problems import rest_cuts, rig_plausibility

from facebasis.retarget.rigdrive import RigRetargeter


def test_before_variants_run_the_former_noise_model():
    assert rig_plausibility.VARIANTS["before"]["noise_model"] == "rig"
    assert rest_cuts.VARIANTS["before"][0]["noise_model"] == "rig"
    assert rest_cuts.VARIANTS["rig_noise"][0] == {"noise_model": "rig"}
    assert rig_plausibility.VARIANTS["before"]["point_noise"] == "shared"      # the former landmark model too
    assert rest_cuts.VARIANTS["before"][0]["point_noise"] == "shared"
    assert rest_cuts.VARIANTS["shared_points"][0] == {"point_noise": "shared"}
    assert rig_plausibility.VARIANTS["before"]["gaze"] == "free" and rest_cuts.VARIANTS["before"][0]["gaze"] == "free"
    assert rest_cuts.VARIANTS["free_gaze"] == ({"gaze": "free"}, True)        # the gaze prior undone
    assert rest_cuts.VARIANTS["previous"] == ({"rest_depth": "none"}, True)   # this round's rest depth undone
    assert rig_plausibility.VARIANTS["before"]["rest_depth"] == "none" and rest_cuts.VARIANTS["before"][0]["rest_depth"] == "none"
    assert rig_plausibility.VARIANTS["flat_rest"] == {"rest_depth": "none"}
    assert inspect.signature(RigRetargeter).parameters["rest_depth"].default == "tangent"
    assert inspect.signature(RigRetargeter).parameters["noise_model"].default == "pixels"   # what "default" runs
    assert inspect.signature(RigRetargeter).parameters["gaze"].default == "conjugate"

