"""Opening a registered device from command-line options (``acquire``, ``calibrate delay-zero``, ``devices``)."""

from __future__ import annotations

import inspect
import json
import math
from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError

#: ``--device-option KEY=VALUE`` (repeatable): any option of the device's factory.
DeviceOptionArg = Annotated[
    list[str] | None,
    typer.Option(
        "--device-option",
        "-O",
        help="Device option KEY=VALUE (repeatable; VALUE as JSON, else text), e.g. -O pixel_clock_mhz=30. "
        "`planeray devices` lists every device's options.",
    ),
]
#: ``--calibration acquisition.json``: the calibrated rig.
CalibrationArg = Annotated[
    Path | None,
    typer.Option(
        help="acquisition.json (or its folder) written by `planeray calibrate`: lines_per_second and "
        "base_trigger_delay_us are read from it (explicit options win)."
    ),
]

#: Fields of acquisition.json that are device options.
CALIBRATION_FIELDS = ("lines_per_second", "base_trigger_delay_us")


def parse_device_options(texts) -> dict:
    """``["KEY=VALUE", ...]`` -> dict; VALUE parsed as JSON when it is JSON (numbers, true, [16, 16]), else text."""
    options = {}
    for text in texts or ():
        key, sep, value = text.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or not key.isidentifier():
            raise InputError(f"--device-option expects KEY=VALUE, got {text!r}")
        try:
            options[key] = json.loads(value)
        except json.JSONDecodeError:
            options[key] = value
    return options


def read_calibration(path) -> dict:
    """The calibration fields of an ``acquisition.json`` (or of ``path/acquisition.json``)."""
    path = Path(path)
    if path.is_dir():
        path = path / "acquisition.json"
    if not path.is_file():
        raise InputError("calibration file not found", path)
    try:
        acq = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"cannot read calibration ({exc})", path) from exc
    if not isinstance(acq, dict):
        raise InputError("expected a JSON object", path)
    found = {}
    for key in CALIBRATION_FIELDS:
        value = acq.get(key)
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise InputError(f"{key} must be a number, got {value!r}", path)
        found[key] = float(value)
    return found


def device_options_from_cli(name: str, explicit: dict, option_texts, calibration) -> dict:
    """The keyword options to open device ``name`` with.

    ``explicit``: the dedicated command-line options (None = not given);
    ``option_texts``: ``--device-option`` values; ``calibration``: an
    acquisition.json whose calibration fields fill the options the device takes
    and that were not given.
    """
    from ..devices import device_options

    accepted = device_options(name)
    options = {k: v for k, v in explicit.items() if v is not None}
    for key, value in parse_device_options(option_texts).items():
        if key in options and options[key] != value:
            raise InputError(f"option {key} given twice (--{key.replace('_', '-')} and --device-option)")
        options[key] = value
    if calibration is not None:
        for key, value in read_calibration(calibration).items():
            if key in accepted:
                options.setdefault(key, value)
    return options


def describe_options(name: str) -> str:
    """``key=default`` of every option of device ``name`` (``key`` alone when required)."""
    from ..devices import device_options

    parts = []
    for key, default in device_options(name).items():
        parts.append(key if default is inspect.Parameter.empty else f"{key}={default!r}")
    return ", ".join(parts)


def close_device(device) -> None:
    """Release a device (devices written without ``close`` have nothing to release)."""
    close = getattr(device, "close", None)
    if close is not None:
        close()
