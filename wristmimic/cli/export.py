"""``wristmimic export RUN -o OUT.h5``: rollouts of a trained policy written as a canonical dataset."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors
from wristmimic.cli.options import device_option


def export_cmd(
    run: Path = typer.Argument(..., help="Training run folder (its checkpoint.pt) or a checkpoint file."),
    out: Path = typer.Option(..., "--out", "-o", help="Canonical .h5 file to write (refused if it exists)."),
    trials: int = typer.Option(
        None, "--trials", "-n", min=1, help="Run N seeded trials as evaluate does (default: one, the policy mean)."
    ),
    successful_only: bool = typer.Option(False, "--successful-only", help="Keep only the trials that succeed."),
    from_eval: Path = typer.Option(
        None, "--from-eval", help="Re-run rows of this evaluation folder's per-trial table by their seeds."
    ),
    rows: str = typer.Option(None, "--rows", help="With --from-eval: trial numbers, e.g. 0-9,42 (default: all)."),
    protocol: str = typer.Option(
        "paper", "--protocol", "-p", help="Protocol of the --trials (eval/protocols name or .toml path)."
    ),
    noise: str = typer.Option(None, "--noise", help="actions or initial-state (default: the protocol's)."),
    seed: int = typer.Option(None, "--seed", min=0, help="Base seed of the trial seeds (default: the protocol's)."),
    deploy_std: float = typer.Option(
        None, "--deploy-std", min=0.0, help="Sigma of the sampled actions (as evaluate; 0: the training sigma)."
    ),
    num_envs: int = typer.Option(256, "--num-envs", min=1, help="Worlds stepped together."),
    nthread: int = typer.Option(None, "--nthread", min=1, help="Physics threads (default: all cores)."),
    weights: str = typer.Option(
        "deployed",
        "--weights",
        help="deployed: the weights the run deploys (the CPU recipe: the best periodic evaluation's); "
        "latest: the last update's.",
    ),
    dataset: Path = typer.Option(None, "--dataset", help="Canonical file to use instead of the run's (same sha256)."),
    backend: str = typer.Option(None, "--backend", help="Physics: cpu or warp (default: cpu, or the evaluation's)."),
    device: str = device_option(),
    force: bool = typer.Option(False, "--force", help="Replace OUT if it exists."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
) -> None:
    """Write simulated rollouts of a trained policy as canonical sequences <scene>__sim_<seed>: root, joint angles,
    body and object poses and contacts from the simulation, plus sim/actions, sim/pd_targets, sim/contact_force and
    provenance; the run's humanoid and objects are copied, so the file trains, evaluates and views like any other.

    Example: wristmimic export runs/RUN -o sim.h5

    Example: wristmimic export runs/RUN -o sim.h5 --trials 1000 --successful-only

    Example: wristmimic export runs/RUN -o sim.h5 --from-eval runs/RUN/eval/paper --rows 0-9
    """
    from wristmimic.evaluate import load_eval_policy, load_protocol
    from wristmimic.evaluate.export import export_rollouts

    with user_errors():
        proto = load_protocol(protocol)
        policy = load_eval_policy(run, weights)
        if deploy_std is not None:
            policy.policy.deploy_std = float(deploy_std)
        r = export_rollouts(
            policy, out, trials=trials, successful_only=successful_only, from_eval=from_eval, rows=rows,
            protocol=proto, noise=noise, seed=seed, num_envs=num_envs, nthread=nthread, dataset=dataset,
            backend=backend, backend_options={"device": device} if device else None, force=force,
            progress=not quiet,
        )  # fmt: skip
        typer.echo(
            f"{r.out}: {len(r.sequences)} sequence(s) of {r.trials_run} trial(s), {r.successes} successful "
            f"({r.seconds:.1f} s)"
        )
