"""``ship-ident bench NAME [--json] [--quick]``: run a registered benchmark (ship_ident/bench)."""
from __future__ import annotations

import json


def add_parser(subparsers) -> None:
    from ..bench import benchmarks

    available = benchmarks()
    parser = subparsers.add_parser(
        "bench", help="run a benchmark of the estimators",
        description="Benchmarks: " + "; ".join(f"{b.name}: {b.description}" for b in available.values()))
    parser.add_argument("name", choices=sorted(available), metavar="NAME",
                        help="one of " + ", ".join(sorted(available)))
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.add_argument("--quick", action="store_true", help="tiny sizes (smoke test, minutes -> seconds)")
    parser.add_argument("--plot-dir", metavar="DIR",
                        help="write the benchmark's figures (PNG) here, for those that draw any")
    parser.set_defaults(func=run)


def run(args) -> int:
    from ..bench import benchmarks

    benchmark = benchmarks()[args.name]
    if benchmark.plots and args.plot_dir:
        result = benchmark.run(args.quick, plot_dir=args.plot_dir)
    else:
        result = benchmark.run(args.quick)
    result = {"benchmark": benchmark.name, "quick": bool(args.quick), **result}
    print(json.dumps(result, allow_nan=True) if args.json else benchmark.render(result))
    return 0
