"""CPU per call of load_model and save_model (issue 30: a model that loads light), each
against json's own work on the same file measured in the same run.

    python benchmarks/model_file.py                 # fits sample_data/calibration first
    python benchmarks/model_file.py m.json ...      # these model files

Baselines: ``json.loads`` of the file's text (load parses it, then checks the digest,
the tables and every figure) and ``json.dumps(doc, indent=1, sort_keys=True)`` of its
document (what save_model's text is, byte for byte).  CPU time (``time.process_time``),
the best of ``--repeats`` batches, so other load on a shared machine inflates both less.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fsdecouple.core.modelfile import load_model, model_to_dict, save_model  # noqa: E402


def cpu_per_call(f, calls: int, repeats: int) -> float:
    """Best of ``repeats`` batches of ``calls`` calls [s of CPU a call]."""
    f()
    best = float("inf")
    for _ in range(repeats):
        t = time.process_time()
        for _ in range(calls):
            f()
        best = min(best, (time.process_time() - t) / calls)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="*", type=Path)
    ap.add_argument("--calls", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=4)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        models = args.models
        if not models:
            from fsdecouple import fit, load_calibration, load_config

            settings = load_config()
            models = [Path(tmp) / "sample.json"]
            save_model(fit(load_calibration(ROOT / "sample_data" / "calibration", settings),
                           settings), models[0])
        out = Path(tmp) / "out.json"
        print(f"load average: {', '.join(f'{v:.2f}' for v in os.getloadavg())}")
        print(f"{'model':<28} {'KB':>6} {'load ms':>8} {'json.loads':>10} {'ratio':>6} "
              f"{'save ms':>8} {'json.dumps':>10} {'ratio':>6}")
        for path in models:
            text = path.read_text(encoding="utf-8")
            model = load_model(path)
            doc = model_to_dict(model)
            load = cpu_per_call(lambda p=path: load_model(p), args.calls, args.repeats)
            parse = cpu_per_call(lambda t=text: json.loads(t), args.calls, args.repeats)
            save = cpu_per_call(lambda m=model: save_model(m, out), args.calls, args.repeats)
            dump = cpu_per_call(
                lambda d=doc: json.dumps(d, indent=1, sort_keys=True, allow_nan=False),
                args.calls, args.repeats)
            print(f"{path.name[-28:]:<28} {len(text) / 1e3:>6.0f} {load * 1e3:>8.1f} "
                  f"{parse * 1e3:>10.1f} {load / parse:>6.2f} {save * 1e3:>8.1f} "
                  f"{dump * 1e3:>10.1f} {save / dump:>6.2f}")


if __name__ == "__main__":
    main()
