"""Add up JUnit XML files into one closing line: ``N passed, N failed, N skipped``.

Exit status 1 if a file is missing, if no test ran at all, if a module could not be collected, or if anything
failed or errored. A collection error is reported by name (pytest counts it as an errored "test", which would
otherwise read as an ordinary failure count of a suite that never ran).
Usage: python scripts/test_summary.py out/test/serial.xml out/test/mpi.xml
"""
import sys
import xml.etree.ElementTree as ET

totals = {"tests": 0, "failures": 0, "errors": 0, "skipped": 0}
uncollected = []
ok = True
for path in sys.argv[1:]:
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as e:
        print(f"test summary: cannot read {path}: {e}", file=sys.stderr)
        ok = False
        continue
    for suite in root.iter("testsuite"):
        for key in totals:
            totals[key] += int(suite.get(key, 0))
    for case in root.iter("testcase"):
        error = case.find("error")
        if error is not None and error.get("message") == "collection failure":
            uncollected.append(f"{case.get('classname') or ''}{case.get('name')} ({path})")
failed = totals["failures"] + totals["errors"] - len(uncollected)
passed = totals["tests"] - totals["failures"] - totals["errors"] - totals["skipped"]
print(f"{passed} passed, {failed} failed, {totals['skipped']} skipped", flush=True)
if totals["tests"] - len(uncollected) == 0:
    print("test summary: no test ran", file=sys.stderr)
    ok = False
if uncollected:
    print("test summary: collection failed for " + ", ".join(uncollected)
          + ": the suite did not run; see the ERROR lines above", file=sys.stderr)
    ok = False
sys.exit(0 if ok and failed == 0 else 1)
