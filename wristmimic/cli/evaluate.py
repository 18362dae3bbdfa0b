"""``wristmimic evaluate RUN_DIR_OR_CHECKPOINT``: the paper's rollout trials for one trained scene policy."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors
from wristmimic.cli.options import backend_option, device_option


def evaluate_cmd(
    run: Path = typer.Argument(..., help="Training run folder (its checkpoint.pt) or a checkpoint file."),
    trials: int = typer.Option(
        None, "--trials", "-n", min=1, help="Trials per scene (default: the protocol's, paper 10,000)."
    ),
    protocol: str = typer.Option(
        "paper", "--protocol", "-p", help="Protocol name in eval/protocols (paper, quick) or a .toml path."
    ),
    split: str = typer.Option(
        None, "--split", help="Split the scene must belong to (eval/splits); default: the first that lists it."
    ),
    num_envs: int = typer.Option(
        256, "--num-envs", min=1, help="Worlds stepped together; each runs trials back to back."
    ),
    nthread: int = typer.Option(None, "--nthread", min=1, help="Physics threads (default: all cores)."),
    out: Path = typer.Option(None, "--out", "-o", help="Output folder (default: RUN_DIR/eval/<protocol>)."),
    noise: str = typer.Option(
        None, "--noise", help="How trials differ: actions (sampled) or initial-state (default: the protocol's)."
    ),
    seed: int = typer.Option(None, "--seed", min=0, help="Base seed of the trial seeds (default: the protocol's)."),
    deploy_std: float = typer.Option(
        None,
        "--deploy-std",
        min=0.0,
        help="Sigma of the sampled actions (default: the run's ppo.deploy_std, else its training sigma); "
        "0: the training sigma. Recorded as action_sigma in eval.json.",
    ),
    weights: str = typer.Option(
        "deployed",
        "--weights",
        help="deployed: the weights the run deploys (the CPU recipe: the best periodic evaluation's); "
        "latest: the last update's. Recorded as policy_weights in eval.json.",
    ),
    dataset: Path = typer.Option(None, "--dataset", help="Canonical file to use instead of the run's (same sha256)."),
    backend: str = backend_option(),
    device: str = device_option(),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
) -> None:
    """Run rollout trials from frame 0 and write <scene>.parquet (one row per trial), summary.json and summary.csv.

    A trial succeeds when it reaches the end of the sequence without early termination, its mean object position
    error is below 10 cm and it keeps hand contact for >= 80 % of the reference contact duration (protocol).
    Completed trials are saved in chunks: after Ctrl-C, rerun the same command to resume; the result is the same.

    Example: wristmimic evaluate runs/sub2_largetable_000-wristmimic-seed0-20261123-120000 --trials 10000

    Example: wristmimic evaluate runs/RUN --protocol quick --noise initial-state -o reports/eval/RUN-quick
    """
    from wristmimic.evaluate import EvalInterrupted, evaluate_policy, load_eval_policy, load_protocol
    from wristmimic.safe_io import check_output_folder

    with user_errors():
        proto = load_protocol(protocol)
        policy = load_eval_policy(run, weights)
        if deploy_std is not None:
            policy.policy.deploy_std = float(deploy_std)
        run_dir = Path(policy.metadata["run_dir"])
        target = out or run_dir / "eval" / proto.name
        check_output_folder(target, "--out" if out else None)
        try:
            r = evaluate_policy(
                policy, proto, target, trials=trials, noise=noise, seed=seed, num_envs=num_envs, nthread=nthread,
                dataset=dataset, split=split, progress=not quiet, backend=backend,
                backend_options={"device": device} if device else None,
            )  # fmt: skip
        except EvalInterrupted as exc:
            typer.echo(f"interrupted: {exc}", err=True)
            raise typer.Exit(code=130) from None
        s = r.summary
        typer.echo(
            f"{s['scene']} [{s['method']}]: success {100 * s['success_rate']:.1f} % "
            f"(95 % CI {100 * s['success_ci_low']:.1f}-{100 * s['success_ci_high']:.1f}) of {s['trials']:,} trials, "
            f"object {s['obj_pos_err_cm']:.1f} cm / {s['obj_rot_err_deg']:.1f} deg; strict (object never "
            f"{100 * proto.max_object_position_error_m:g} cm off) {100 * s['strict_success_rate']:.1f} % -> {r.out}"
        )
