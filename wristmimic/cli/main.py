"""The ``wristmimic`` command: one Typer app, one thin module per verb."""

from __future__ import annotations

import typer

from wristmimic import __version__
from wristmimic.cli import convert, demo, humanoid, inspect, pipeline, scene, train, validate
from wristmimic.cli import evaluate as evaluate_cli
from wristmimic.cli import export as export_cli
from wristmimic.cli import report as report_cli
from wristmimic.cli import synth as synth_cli
from wristmimic.cli import view as view_cli

app = typer.Typer(
    name="wristmimic",
    help="Physics-based human-object-interaction retargeting (WristMimic) on MuJoCo.\n\n"
    "Data flow: convert (source files -> canonical HDF5) -> scene/env -> train -> evaluate -> report / view.",
    no_args_is_help=True,
    pretty_exceptions_show_locals=False,
    add_completion=False,
)
app.add_typer(convert.app, name="convert")
app.add_typer(humanoid.app, name="humanoid")
app.command("inspect")(inspect.inspect_cmd)
app.command("validate")(validate.validate_cmd)
app.command("scene")(scene.scene_cmd)
app.command("train")(train.train_cmd)
app.command("evaluate")(evaluate_cli.evaluate_cmd)
app.command("export")(export_cli.export_cmd)
app.command("report")(report_cli.report_cmd)
app.command("run")(pipeline.run_cmd)
app.command("synth")(synth_cli.synth_cmd)
app.command("view")(view_cli.view_cmd)
app.command("demo")(demo.demo_cmd)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"wristmimic {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version."),
) -> None:
    """Physics-based HOI retargeting suite."""


if __name__ == "__main__":
    app()
