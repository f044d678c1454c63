"""The system's chromium driven by Playwright, for the browser tests (nothing downloads a browser)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

from planeray.viewer.browser import chromium_args, find_chromium


def system_chromium(unavailable: Callable[[str], None]) -> Iterator:
    """Yield a launched Playwright browser on the system's chromium; ``unavailable(reason)`` skips or fails."""
    path = find_chromium()
    if path is None:
        unavailable("no chromium on this machine: `apt-get install chromium` (make test does it as root)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        unavailable("playwright is not installed: pip install -e '.[test]'")
    pw = sync_playwright().start()
    try:
        b = pw.chromium.launch(executable_path=path, args=chromium_args())
        yield b
        b.close()
    finally:
        pw.stop()
