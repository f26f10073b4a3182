"""``composed-sim bench --replot runs.json …``: the CSV, JSON, figures and report redrawn from the
stored rows of one or several sweeps (of the same tick count), merged into one document."""
from __future__ import annotations

import json
import sys

from composed_sim.bench.arguments import BenchSettings
from composed_sim.bench.report import write_outputs


def replot(args: BenchSettings) -> int:
    """``--replot runs.json …``: the outputs and the report redrawn from the rows of one or several sweeps."""
    from composed_sim.command_line import UserError, check_writable
    docs = []
    for path in args.replot:
        try:
            doc = json.loads(path.read_text())
            doc["rows"], doc["machine"], doc["settings"]["ticks"]
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise UserError(f"--replot {path}: not a runs.json of composed-sim bench ({e})") from None
        docs.append(doc)
    ticks = {d["settings"]["ticks"] for d in docs}
    if len(ticks) > 1:
        raise UserError(f"--replot: the sweeps ran different tick counts ({', '.join(map(str, sorted(ticks)))}); "
                        "their runs cannot share a table")
    doc = merged_sweeps(docs)
    check_writable(args.out)
    if args.report is not None:
        check_writable(args.report.parent / "figures")
    write_outputs(doc, args.out, args.report)
    print(f"bench: redrew {len(doc['rows'])} runs from {', '.join(map(str, args.replot))} into {args.out}/"
          + (f" and {args.report}" if args.report else ""), file=sys.stderr)
    return 0


def merged_sweeps(docs: list[dict]) -> dict:
    """One runs.json document of several sweeps' (the same tick count): their rows in the order
    given, each sweep's command on a line of its own, the settings' lists joined; the machine is
    the first sweep's (its date and load, the others' commits named too)."""
    if len(docs) == 1:
        return docs[0]

    def union(key):
        out = []
        for d in docs:
            out += [v for v in d["settings"].get(key, []) if v not in out]
        return out
    first = docs[0]
    settings = {**first["settings"], "modes": union("modes"), "executors": union("executors"),
                "workers": union("workers"), "sizes": sorted(union("sizes")),
                "trials": max(d["settings"].get("trials", 1) for d in docs),
                "experiments": {k: v for d in docs for k, v in d["settings"].get("experiments", {}).items()}}
    commits = [c for c in dict.fromkeys(d["machine"].get("commit") for d in docs) if c]
    measured = [d["memory_estimate"] for d in docs if d.get("memory_estimate")
                and not d["memory_estimate"].get("source", "").startswith("not measured")]
    columns = [c for d in docs for c in d.get("columns", [])]
    return {**first, "command": "\n".join(d.get("command", "composed-sim bench") for d in docs),
            "machine": {**first["machine"], "commit": ", ".join(commits) or None},
            "settings": settings, "elapsed_s": sum(d.get("elapsed_s", 0) for d in docs),
            "interrupted": any(d.get("interrupted") for d in docs),
            "memory_estimate": measured[-1] if measured else first.get("memory_estimate"),
            "calibration_runs": [r for d in docs for r in d.get("calibration_runs", [])],
            "columns": list(dict.fromkeys(columns)), "rows": [r for d in docs for r in d["rows"]]}
