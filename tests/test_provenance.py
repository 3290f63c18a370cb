"""The provenance record as a study result: complete, serialisable, reproducible by its command."""

import json
import subprocess
import sys

from common.result import Status
from comparisons.provenance import provenance_study


def test_provenance_is_a_complete_result_with_a_real_command():
    r = provenance_study()
    assert r.status is Status.PASSED and r.complete_pass and not r.checks
    json.dumps(r.to_dict())
    assert r.data["cpu"] and r.data["numpy"] and r.command == "python -m comparisons.provenance"
    out = subprocess.run(
        [sys.executable, "-m", "comparisons.provenance"], capture_output=True, text=True, check=True
    )
    assert json.loads(out.stdout)["numpy"] == r.data["numpy"]
