"""One line per lock file from pip-audit's JSON report: how many packages were audited, how many could not be (and
why), the known vulnerabilities (exit 1 if any). No report at all (the service unreachable) is said as such."""

import json
import sys
from collections import Counter
from pathlib import Path

lock, report, errors = sys.argv[1:4]
try:
    dependencies = json.loads(Path(report).read_text())["dependencies"]
except (OSError, ValueError, KeyError):
    last = (Path(errors).read_text().strip().splitlines() or ["no output"])[-1]
    print(f"dependency audit of {lock}: no verdict, pip-audit gave no report ({last[:200]})")
    sys.exit(0)
skipped = [d for d in dependencies if "skip_reason" in d]
audited = len(dependencies) - len(skipped)
vulnerable = [(d["name"], d["version"], [v["id"] for v in d["vulns"]]) for d in dependencies if d.get("vulns")]
if audited == 0:
    reason = Counter(d["skip_reason"].split(":")[0] for d in skipped).most_common(1)[0][0]
    print(f"dependency audit of {lock}: no verdict, 0 of {len(dependencies)} locked packages could be audited (pip-audit: {reason})")
    sys.exit(0)
print(f"dependency audit of {lock}: {audited} of {len(dependencies)} packages audited, {len(skipped)} could not be, "
      f"{len(vulnerable)} with known vulnerabilities" + "".join(f"\n  {n} {v}: {', '.join(ids)}" for n, v, ids in vulnerable))
sys.exit(1 if vulnerable else 0)
