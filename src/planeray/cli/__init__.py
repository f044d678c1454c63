"""Command-line interface: a thin shell over the library (typer + rich).

Every command that takes a stack accepts a native Zarr stack or a captured
import folder (``manifest.csv`` + images + ``acquisition.json``).  Bad input
prints one line naming the file and the problem and exits with status 1.

One module per command group; this file names the commands (in ``planeray --help``
order) and holds the entry point:

* ``simulate.py``   scenes, simulate (built-in scenes on the simulated Episcan)
* ``render.py``     render, render-examples (a Mitsuba 3 scene file -> transport store, planeray.render)
* ``stacks.py``     info, export, import (describe a stack; the import folder format)
* ``acquire.py``    acquire (a sweep from a device into a resumable native stack), devices (the registry)
* ``demux.py``      demux (stack -> 3D light transport, Sec. 4)
* ``analysis.py``   contact-sheet, profiles, synth, figure (look at stacks and transports)
* ``baselines.py``  emulate, separate direct-global (conventional projector-camera)
* ``calibrate.py``  calibrate lines | simulate-lines | delay-zero (Sec. 6)
* ``rig.py``        project (the projector window), rig check (is the rig wired and set up right?)
* ``mc.py``         mc profile (Monte Carlo subsurface scattering, Sec. 5.2)
* ``study.py``      study demux (the Sec. 5.2 study)
* ``materials.py``  materials classes | simulate | train | predict | report (Sec. 8, Fig. 10)
* ``skin.py``       skin simulate | validate | veins | enhance | compare (veins through skin, Sec. 10, Figs. 13, 14, 16)
* ``pulse.py``      skin pulse | video | pulse-report (the pulse, Sec. 10, Fig. 15), on the skin group
* ``paper.py``      paper (every figure of the paper, resumable, with a report beside the paper's numbers)
* ``view.py``       view (the live explorer in the browser), video (a delay or exposure sweep as a video)
* ``sweep.py``      sweep design | show (the few images that determine the transport best; a sweep drawn)
* ``demo.py``       demo (``make demo``)
* ``_devices.py``   opening a registered device from options (--device-option, --calibration)
* ``_common.py``    shared helpers: one-line errors, stack loading, ``--pixel`` parsing, image saving

The consoles and the progress bar are in :mod:`planeray._console` (shared with the demo).
"""

from __future__ import annotations

import typer

from . import (
    acquire,
    analysis,
    baselines,
    calibrate,
    demo,
    demux,
    materials,
    mc,
    paper,
    pulse,
    render,
    rig,
    simulate,
    skin,
    stacks,
    study,
    sweep,
    view,
)
from ._common import DEBUG, PlanerayGroup, _friendly_errors, _join_pixel_args

__all__ = ["app", "main"]

app = typer.Typer(
    help="planeray: programmable plane-to-ray light transport (simulate, capture, analyse delay-exposure stacks).",
    cls=PlanerayGroup,
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # help as wide as the terminal, up to 120 columns (click's own cap is 80)
    context_settings={"max_content_width": 120},
)


def _print_version(value: bool) -> None:
    if value:
        from ..io import planeray_version

        typer.echo(f"planeray {planeray_version()}")
        raise typer.Exit()


@app.callback()
def _options(
    debug: bool = typer.Option(False, "--debug", help="Show the traceback of an error instead of one line."),
    version: bool = typer.Option(
        False, "--version", "-V", is_eager=True, callback=_print_version, help="Print the version and exit."
    ),
):
    """planeray: programmable plane-to-ray light transport (simulate, capture, analyse delay-exposure stacks)."""
    DEBUG["enabled"] = debug


# Commands, in the order `planeray --help` lists them.
app.command()(simulate.scenes)
app.command()(simulate.simulate)
app.command()(render.render)
app.command("render-examples")(render.render_examples)
app.command()(stacks.info)
app.command("contact-sheet")(analysis.contact_sheet)
app.command()(analysis.profiles)
app.command()(acquire.acquire)
app.command()(acquire.devices)
app.command()(rig.project)
app.command()(baselines.emulate)
app.command()(demux.demux)
app.command()(analysis.synth)
app.command()(analysis.figure)
app.command()(paper.paper)
app.command()(stacks.export)
app.command("import")(stacks.import_)
app.command()(view.view)
app.command()(view.video)
app.command()(demo.demo)
# Command groups (sub-apps).
app.add_typer(baselines.separate_app, name="separate")
app.add_typer(sweep.sweep_app, name="sweep")
app.add_typer(calibrate.calibrate_app, name="calibrate")
app.add_typer(rig.rig_app, name="rig")
app.add_typer(mc.mc_app, name="mc")
app.add_typer(study.study_app, name="study")
app.add_typer(materials.materials_app, name="materials")
app.add_typer(skin.skin_app, name="skin")
# The pulse commands of the skin group (Sec. 10, Fig. 15).
skin.skin_app.command("pulse")(_friendly_errors(pulse.pulse))
skin.skin_app.command("video")(_friendly_errors(pulse.video))
skin.skin_app.command("pulse-report")(_friendly_errors(pulse.pulse_report))


def _first_sentence(doc: str) -> str:
    """The first sentence of a docstring (click's own short help stops at any word ending in a dot: "Figs.")."""
    import inspect
    import re

    paragraph = " ".join(inspect.cleandoc(doc).split("\n\n")[0].split())
    return re.split(r"(?<=[.!?])\s+(?=[A-Z`])", paragraph, maxsplit=1)[0]


def _plain_help(typer_app: typer.Typer) -> None:
    """Click's own help layout for ``typer_app`` and its groups: at 80 columns it wraps the help text under
    whole option names (rich's panels cut long names, ``--lines-per-seco…``, and print ``<bool>`` on flags)."""
    typer_app.rich_markup_mode = None
    for info in typer_app.registered_commands:
        if info.short_help is None and info.help is None and info.callback is not None:
            info.short_help = _first_sentence(info.callback.__doc__ or "")
    for group in typer_app.registered_groups:
        info = group.typer_instance.info
        callback = group.callback or info.callback
        docs = [group.help, info.help, getattr(callback, "__doc__", None)]
        doc = next((d for d in docs if isinstance(d, str) and d.strip()), None)
        if not isinstance(group.short_help, str) and not isinstance(info.short_help, str) and doc:
            group.short_help = _first_sentence(doc)
        _plain_help(group.typer_instance)


_plain_help(app)


def main(argv: list[str] | None = None):
    """Console entry point (``planeray``).

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``planeray`` (default: the process's own).

    Returns
    -------
    None
        Ends with ``SystemExit``: status 0, or 1 after a one-line error.

    See Also
    --------
    planeray.demo.run_demo : the demo's workflow as a function.

    Examples
    --------
    The command line from Python (what the ``planeray`` command runs); it ends with the exit status:

    >>> import contextlib, io
    >>> out = io.StringIO()
    >>> with contextlib.redirect_stdout(out):
    ...     try:
    ...         main(["scenes"])
    ...     except SystemExit as done:
    ...         status = done.code
    >>> status, "translucent wax object" in out.getvalue()
    (0, True)
    """
    import sys

    args = _join_pixel_args(list(sys.argv[1:] if argv is None else argv))
    app(args=args, prog_name="planeray")


if __name__ == "__main__":  # pragma: no cover
    main()
