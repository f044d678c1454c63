"""Print how long each gallery example took at the last docs build (slowest first): a report, not a gate.

``make docs`` runs it after the site's tests.  The times come from each example's page ("Total running
time of the script"), written by sphinx-gallery as the example ran; a busy machine makes them longer.

Usage: python tools/gallery_times.py [SITE]   (default docs/_build/html)
"""

from __future__ import annotations

import html
import re
import sys
from pathlib import Path

TIME = re.compile(r"Total running time of the script:\s*\(\s*(\d+) minutes\s+([\d.]+) seconds\)")


def example_times(site: Path) -> dict[str, float]:
    """Seconds per example (its page's stem), from the built pages."""
    times = {}
    for page in sorted((site / "auto_examples").glob("plot_*.html")):
        text = " ".join(html.unescape(re.sub(r"<[^>]+>", " ", page.read_text(encoding="utf-8"))).split())
        m = TIME.search(text)
        if m:
            times[page.stem] = 60 * int(m.group(1)) + float(m.group(2))
    return times


def main(argv: list[str]) -> int:
    site = Path(argv[0] if argv else "docs/_build/html")
    times = example_times(site)
    if not times:
        print(f"gallery times: no example pages under {site / 'auto_examples'}")
        return 0
    print(f"gallery examples, {len(times)} ran in {sum(times.values()):.0f} s in all (slowest first):")
    for name, seconds in sorted(times.items(), key=lambda kv: -kv[1]):
        print(f"  {seconds:6.1f} s  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
