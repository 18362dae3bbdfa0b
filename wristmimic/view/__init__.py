"""Rerun recordings (``.rrd``) of a reference sequence and of a simulated rollout beside it.

>>> from wristmimic.view import record_reference, record_rollout
>>> record_reference("datasets/omomo.h5", "sub2_largetable_000", "ref.rrd")
>>> record_rollout(env, evaluation_actor(policy, trial_seed=None), "rollout.rrd")  # env: WristMimicEnv
"""

from wristmimic.view.record import RecordingSummary, record_reference, record_rollout, trial_metrics, write_recording
from wristmimic.view.rollout import evaluation_actor, run_rollout
from wristmimic.view.run import RunViewOptions, record_run

__all__ = [
    "RecordingSummary",
    "RunViewOptions",
    "evaluation_actor",
    "record_reference",
    "record_rollout",
    "record_run",
    "run_rollout",
    "trial_metrics",
    "write_recording",
]
