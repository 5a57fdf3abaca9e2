"""Make docs/img/report.png: the README's screenshot of a report (sample log, camera front).

    python benchmarks/report_screenshot.py

Renders the three-camera sample's report, keeps the verdict and the first camera's signed
error and rolling Eq. 5 plots, and shoots it with headless Chromium (tests/browser.py).
"""

from __future__ import annotations

import re
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from browser import screenshot  # noqa: E402
from syncaudit.audit.run import audit_log  # noqa: E402
from syncaudit.report.html import audit_sections, page, time_origin_ns  # noqa: E402
from syncaudit.rig import load_rig  # noqa: E402


def main() -> None:
    log = REPO / "sample_logs" / "vlp16_three_cameras.mcap"
    result = audit_log(log, load_rig(Path(f"{log}.rig.yaml")))
    body = audit_sections(result)
    head = body[: body.index("</h1>") + 5]
    front = body[body.index('<section class="camera"') :]
    figures = re.findall(
        r'<figure class="tplot" data-kind="(?:error|rolling-mean)".*?</figure>', front, re.S
    )
    html = page(
        "syncaudit report",
        head + "<h2>camera front: needs correction</h2>" + "".join(figures[:2]),
        t0_ns=time_origin_ns(result),
    )
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "shot.html"
        src.write_text(html)
        shot = screenshot(src, "readme/report.png", width=1060, height=640)
    out = REPO / "docs" / "img" / "report.png"
    out.write_bytes(shot.read_bytes())
    print(f"{out}: {out.stat().st_size} bytes")


if __name__ == "__main__":
    main()
