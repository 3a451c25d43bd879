"""Add up JUnit XML files into one closing line: ``N passed, N failed, N skipped``.

Exit status 1 if a file is missing, if no test ran at all, or if anything failed or errored.
Usage: python scripts/test_summary.py out/test/serial.xml out/test/mpi.xml
"""
import sys
import xml.etree.ElementTree as ET

totals = {"tests": 0, "failures": 0, "errors": 0, "skipped": 0}
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
failed = totals["failures"] + totals["errors"]
passed = totals["tests"] - failed - totals["skipped"]
if totals["tests"] == 0:
    print("test summary: no test ran", file=sys.stderr)
    ok = False
print(f"{passed} passed, {failed} failed, {totals['skipped']} skipped")
sys.exit(0 if ok and failed == 0 else 1)
