"""Evaluation: the paper's protocol (10,000 trials per scene) as data, seeded replayable trials, Parquet tables.

>>> from wristmimic.evaluate import evaluate_policy, load_eval_policy, load_protocol
>>> evaluate_policy(load_eval_policy("runs/RUN"), load_protocol("paper"), Path("runs/RUN/eval/paper"))
"""

from wristmimic.evaluate.metrics import TRIAL_COLUMNS, wilson_interval
from wristmimic.evaluate.policy import EvalPolicy, RunPolicy, load_eval_policy
from wristmimic.evaluate.protocol import Protocol, Split, load_protocol, load_split
from wristmimic.evaluate.runner import EvalInterrupted, EvalResult, evaluate_policy
from wristmimic.evaluate.trials import TrialSettings, run_trials

__all__ = [
    "TRIAL_COLUMNS",
    "EvalInterrupted",
    "EvalPolicy",
    "EvalResult",
    "Protocol",
    "RunPolicy",
    "Split",
    "TrialSettings",
    "evaluate_policy",
    "load_eval_policy",
    "load_protocol",
    "load_split",
    "run_trials",
    "wilson_interval",
]
