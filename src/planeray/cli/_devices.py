"""Opening a registered device from command-line options (``acquire``, ``calibrate delay-zero``, ``devices``)."""

from __future__ import annotations

import inspect
import json
import math
from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from . import _limits as lim
from ._common import _as_typed

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


def read_calibration(path, *, fields=None) -> dict:
    """The calibration fields of an ``acquisition.json`` (or of ``path/acquisition.json``).

    ``fields``: the numeric fields to read (default :data:`CALIBRATION_FIELDS`).
    """
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
    for key in CALIBRATION_FIELDS if fields is None else fields:
        value = acq.get(key)
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise InputError(f"{key} must be a number, got {value!r}", path)
        found[key] = float(value)
    return found


def device_options_from_cli(name: str, explicit: dict, option_texts, calibration, *, spellings: dict | None = None):
    """The keyword options to open device ``name`` with.

    ``explicit``: the dedicated command-line options (None = not given);
    ``option_texts``: ``--device-option`` values; ``calibration``: an
    acquisition.json whose calibration fields fill the options the device takes
    and that were not given.  ``spellings``, when given, is filled with where each
    option came from, as the user typed it (``--size``, ``-O size``,
    ``--calibration FILE: lines_per_second``), for messages.
    """
    from ..devices import device_options

    accepted = device_options(name)
    spelled = {} if spellings is None else spellings
    options = {k: v for k, v in explicit.items() if v is not None}
    spelled.update({k: "--" + k.replace("_", "-") for k in options})
    for key, value in parse_device_options(option_texts).items():
        if key in options and options[key] != value:
            raise InputError(f"option {key} given twice (--{key.replace('_', '-')} and --device-option)")
        options[key] = value
        spelled.setdefault(key, f"-O {key}")
    if calibration is not None:
        try:
            fields = read_calibration(calibration)
        except InputError as exc:
            raise InputError(f"--calibration {exc}") from None
        if not fields:
            raise InputError(
                f"--calibration {calibration}: no calibration field ({', '.join(CALIBRATION_FIELDS)}) in it; "
                "`planeray calibrate ... --write FILE` writes them"
            )
        for key, value in fields.items():
            if key in accepted and key not in options:
                options[key] = value
                spelled[key] = f"--calibration {calibration}: {key}"
    return options


#: Device options whose meaning is the same on every device, checked like the command's own options.
_COMMON_CHECKS = {
    "scene": lambda v, o: lim.scene(v, o) if isinstance(v, str) else None,
    "size": lambda v, o: lim.size(v, o),
    "projector_rows": lambda v, o: lim.projector_rows(v, o),
    "seed": lambda v, o: lim.seed(v, o),
    "lines_per_second": lambda v, o: lim.lines_per_second(v, o),
    "base_trigger_delay_us": lambda v, o: lim.nonnegative(v, o, maximum=lim.MAX_TIME_US),
    "camera_id": lambda v, o: lim.integer(v, o, minimum=0, maximum=254),
}


def _type_problem(value, default) -> str | None:
    """What is wrong with ``value`` for an option whose default is ``default`` (None: nothing known)."""
    import numbers

    if default is None or default is inspect.Parameter.empty:
        return None
    if isinstance(default, bool):
        return None if isinstance(value, bool) else "true or false"
    if isinstance(default, numbers.Real):
        ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
        return None if ok else "a number"
    if isinstance(default, str):
        return None if isinstance(value, str) else "text"
    if isinstance(default, (tuple, list)):
        return None if isinstance(value, (tuple, list)) else f"a list like {json.dumps(list(default))}"
    return None


def check_device_options(options: dict, spellings: dict, defaults: dict | None = None) -> None:
    """Check the options every device means alike (size, seed, lines per second...), named as typed.

    ``defaults`` (the device's options and defaults): a value of another type than
    its default (``-O noise=3`` for a true/false option) is refused too.
    """
    for key, value in options.items():
        problem = _type_problem(value, (defaults or {}).get(key))
        if problem is not None:
            raise InputError(f"{spellings.get(key, key)} must be {problem}, got {value!r}")
        check = _COMMON_CHECKS.get(key)
        if key == "camera_id" and not isinstance((defaults or {}).get(key), int):
            check = None  # a uEye camera's number; a GenICam camera's id or serial number is text
        if check is not None and value is not None:
            if key == "size" and isinstance(value, list):
                value = tuple(value)
            check(value, spellings.get(key, "--" + key.replace("_", "-")))


def open_device_from_cli(name: str, explicit: dict, option_texts, calibration, *, check=None):
    """Open device ``name`` from command-line options; every refusal names the option as typed.

    The options are assembled as :func:`device_options_from_cli` does and checked
    (:func:`check_device_options`, then ``check(options)`` if given) before the device
    opens; a device that refuses an option (a message ``size must ...``) or fails on a
    value of the wrong type gives one line naming it (``-O size``, ``--size``).
    """
    from ..devices import device_options, list_devices, open_device

    if name not in list_devices():
        raise InputError(
            f"--device {name}: unknown device; choose one of {', '.join(list_devices())} (`planeray devices`)"
        )
    spellings: dict = {}
    options = device_options_from_cli(name, explicit, option_texts, calibration, spellings=spellings)
    accepted = device_options(name)
    for key in options:
        if key not in accepted:
            raise InputError(
                f"{spellings.get(key, key)}: device {name!r} has no option {key!r} (`planeray devices` lists the "
                "options of every device)"
            )
    check_device_options(options, spellings, accepted)
    if check is not None:
        check(options)
    try:
        return open_device(name, **options)
    except InputError as exc:
        text = _as_typed(str(exc), spellings)
        if "replay" in options and str(options["replay"]) in text and "--replay" not in text:
            text = f"--replay {text}"  # the recording the replay device serves
        raise InputError(text) from None
    except (TypeError, ValueError, OverflowError, KeyError) as exc:
        given = ", ".join(f"{spellings.get(k, k)}={v!r}" for k, v in options.items()) or "no options"
        raise InputError(
            f"device {name!r} cannot open with {given}: {_as_typed(str(exc), spellings)} "
            "(`planeray devices` lists each device's options and defaults)"
        ) from None


def describe_options(name: str) -> str:
    """``key=default`` of every option of device ``name`` (``key`` alone when required), as ``-O`` takes them.

    Defaults are written as ``-O`` parses them (JSON: ``size=[128, 128]``,
    ``noise=true``, ``projector_rows=null``), floats rounded to 6 significant digits.
    """
    from ..devices import device_options

    parts = []
    for key, default in device_options(name).items():
        parts.append(key if default is inspect.Parameter.empty else f"{key}={_as_json(default)}")
    return ", ".join(parts)


def _as_json(value) -> str:
    if isinstance(value, float) and math.isfinite(value):
        text = f"{value:.6g}"
        return text if any(c in text for c in ".e") else text + ".0"
    if isinstance(value, tuple):
        value = list(value)
    if isinstance(value, str):  # text as typed, unless it would read as JSON
        try:
            json.loads(value)
        except json.JSONDecodeError:
            return value
    try:
        return json.dumps(value)
    except (TypeError, ValueError):
        return repr(value)


def screen_options(name: str, screen, display, option_texts) -> dict:
    """The device options that plug a simulated projector into ``--screen`` (and ``--display``).

    A device that takes a ``screen`` option (the simulated Episcan: the X screen its
    projector shows) is given the command's ``--screen`` unless ``-O screen=...``
    says otherwise (``-O screen=0 --screen 1``: the projector cable on another
    screen than the window's).
    """
    from ..devices import device_options

    if screen is None or "screen" not in device_options(name):
        return {}
    given = parse_device_options(option_texts)
    found = {}
    if "screen" not in given:
        found["screen"] = screen
    if display is not None and "display" not in given and "display" in device_options(name):
        found["display"] = display
    return found


def close_device(device) -> None:
    """Release a device (devices written without ``close`` have nothing to release)."""
    close = getattr(device, "close", None)
    if close is not None:
        close()
