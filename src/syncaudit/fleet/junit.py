"""JUnit XML of a gate run: one testsuite per log, one testcase per check.

Follows the JUnit XML schema CI systems read (Jenkins/GitLab/GitHub test reporters):
`testsuites > testsuite(name, tests, failures, errors, skipped, time) > testcase(name,
classname, time)` with `failure`/`error` children carrying `message` and `type`. A
failed `warn` check passes with a `system-out` line saying so; a log that could not be
audited is one testcase `audit` with an `error`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from syncaudit.fleet.checks import shown_limit, shown_value
from syncaudit.fleet.record import JudgedLog


def render_junit(logs: list[JudgedLog]) -> str:
    """The JUnit XML document for these verdicts."""
    root = ET.Element("testsuites", name="syncaudit gate")
    totals = {"tests": 0, "failures": 0, "errors": 0}
    for log in logs:
        suite = ET.SubElement(root, "testsuite", name=log.path)
        props = ET.SubElement(suite, "properties")
        for name, value in (
            ("vehicle", log.job.vehicle or ""),
            ("verdict", log.verdict),
            ("fingerprint", log.fingerprint),
            ("skipped_unchanged", str(log.skipped).lower()),
        ):
            ET.SubElement(props, "property", name=name, value=value)
        tests = failures = errors = 0
        if log.error is not None:
            case = ET.SubElement(suite, "testcase", name="audit", classname=log.path, time="0")
            ET.SubElement(case, "error", message=log.error, type=f"exit {log.error_code}")
            tests, errors = 1, 1
        elif not log.checks or log.camera_count == 0:
            case = ET.SubElement(
                suite, "testcase", name="cameras judged", classname=log.path, time="0"
            )
            if log.verdict == "fail":
                ET.SubElement(
                    case, "failure", message="no camera to judge in this log", type="fail"
                )
                failures += 1
            tests += 1
        for check in log.checks:
            case = ET.SubElement(
                suite,
                "testcase",
                name=f"{check.subject}: {check.check}",
                classname=f"{log.path}.{check.scope}",
                time="0",
            )
            tests += 1
            if check.passed:
                continue
            if check.severity == "fail":
                failures += 1
                ET.SubElement(
                    case, "failure", message=check.message, type="fail"
                ).text = f"measured {shown_value(check)}, limit {shown_limit(check)}"
            else:
                ET.SubElement(case, "system-out").text = f"WARNING (warn severity): {check.message}"
        suite.set("tests", str(tests))
        suite.set("failures", str(failures))
        suite.set("errors", str(errors))
        suite.set("skipped", "0")
        suite.set("time", f"{log.elapsed_s:.3f}")
        totals["tests"] += tests
        totals["failures"] += failures
        totals["errors"] += errors
    for name, total in totals.items():
        root.set(name, str(total))
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
