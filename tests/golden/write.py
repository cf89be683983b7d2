"""Write a golden snapshot on this machine: ``python -m tests.golden.write FOLDER_NAME`` from the repository root.

Every case of :data:`tests.golden.CASES` is run with the code checked out, and written with ``platform.json`` (this
machine's numeric platform, the versions that compute, the commit). Write one only from code whose records you have
checked against an existing snapshot (on its platform bit for bit, elsewhere by the cross-machine test): a snapshot is
the refactor guard of every later commit on its platform.
"""

from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime

from sfl_brain.recording.provenance import source_commit

from . import CASES, HERE, ROOT, platform_now, run_case


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("name", help="the snapshot's folder under tests/golden, e.g. x86_64-avx2")
    parser.add_argument("--note", default="", help="a line saying how the snapshot was checked")
    args = parser.parse_args()
    folder = HERE / args.name
    folder.mkdir(exist_ok=True)
    for name in CASES:
        rows = run_case(name)
        (folder / f"{name}.jsonl").write_text("".join(json.dumps(row, sort_keys=True) + "\n" for row in rows))
        print(f"{name}: {len(rows)} rows")
    commit, dirty = source_commit(ROOT)
    about = {
        **platform_now(),
        "exact": True,
        "commit": commit,
        "uncommitted_changes": dirty,
        "written": datetime.now(UTC).isoformat(timespec="seconds"),
        "note": args.note,
    }
    (folder / "platform.json").write_text(json.dumps(about, indent=2) + "\n")
    print(f"wrote {folder.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
