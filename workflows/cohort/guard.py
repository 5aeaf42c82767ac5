"""Runs one step of the cohort workflow so that a failing patient fails alone.

    guard.py --log LOG [--in PATH ...] [--dir-out DIR ...] [--json-out FILE ...] -- COMMAND

If an input is a failure record (a folder holding FAILED.json, or a JSON file with
"failed": true), the step does not run and its outputs become failure records naming that
input. Otherwise COMMAND runs in bash with its output in LOG; if it fails, the outputs become
failure records holding the command's last lines. Either way the step itself succeeds, so the
workflow goes on with the other patients and the results table lists the failure (its
"status" and "error" columns). Delete a failed patient's folders (or use --forcerun) to retry.
"""

import json
import os
import shutil
import subprocess
import sys


def failure_of(path):
    """The error recorded at `path` if it is a failure record, else None."""
    if os.path.isdir(path):
        marker = os.path.join(path, "FAILED.json")
        if os.path.isfile(marker):
            with open(marker) as f:
                return json.load(f).get("error", "failed")
    elif path.endswith(".json") and os.path.isfile(path):
        try:
            with open(path) as f:
                d = json.load(f)
        except (OSError, ValueError):
            return None
        if isinstance(d, dict) and d.get("failed"):
            return d.get("error", "failed")
    return None


def write_failures(dirs, files, error):
    record = {"failed": True, "error": error}
    for d in dirs:
        shutil.rmtree(d, ignore_errors=True)
        os.makedirs(d)
        with open(os.path.join(d, "FAILED.json"), "w") as f:
            json.dump(record, f, indent=2)
    for p in files:
        os.makedirs(os.path.dirname(p) or ".", exist_ok=True)
        with open(p, "w") as f:
            json.dump(record, f, indent=2)


def main(argv):
    split = argv.index("--")
    opts, command = argv[:split], argv[split + 1:]
    log, inputs, dirs, files = None, [], [], []
    i = 0
    while i < len(opts):
        key, value = opts[i], opts[i + 1]
        if key == "--log":
            log = value
        elif key == "--in":
            inputs.append(value)
        elif key == "--dir-out":
            dirs.append(value)
        elif key == "--json-out":
            files.append(value)
        else:
            raise SystemExit(f"guard.py: unknown option {key}")
        i += 2
    os.makedirs(os.path.dirname(log) or ".", exist_ok=True)
    for path in inputs:
        error = failure_of(path)
        if error is not None:
            with open(log, "w") as f:
                f.write(f"not run: {path} failed: {error}\n")
            write_failures(dirs, files, error)
            return 0
    with open(log, "w") as f:
        code = subprocess.call(["bash", "-c", " ".join(command)], stdout=f, stderr=subprocess.STDOUT)
    if code != 0:
        with open(log) as f:
            lines = [l.strip() for l in f.read().splitlines() if l.strip()]
        error = " ".join(lines[-3:]) or f"exit code {code}"
        write_failures(dirs, files, error)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
