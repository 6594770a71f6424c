"""``ship-ident bench NAME [--json] [--quick]``: run a registered benchmark (ship_ident/bench)."""

from __future__ import annotations

import json

from . import SUMMARIES


def add_parser(subparsers) -> None:
    from ..bench import benchmarks

    available = benchmarks()
    parser = subparsers.add_parser(
        "bench",
        help=SUMMARIES["bench"],
        description="Benchmarks: " + "; ".join(f"{b.name}: {b.description}" for b in available.values()),
    )
    parser.add_argument(
        "name", choices=sorted(available), metavar="NAME", help="one of " + ", ".join(sorted(available))
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.add_argument("--quick", action="store_true", help="tiny sizes (smoke test, minutes -> seconds)")
    parser.add_argument(
        "--plot-dir", metavar="DIR", help="write the benchmark's figures (PNG) here, for those that draw any"
    )
    parser.add_argument(
        "--seed", type=int, metavar="N", help="randomised benchmarks: replay this seed (default: a fresh one, printed)"
    )
    parser.add_argument(
        "--count", type=int, metavar="N", help="randomised benchmarks: how many vessels or cases to draw"
    )
    parser.add_argument(
        "--generator",
        metavar="NAME",
        help="benchmarks with several generators of recordings: "
        + "; ".join(f"{b.name}: {', '.join(b.generators)}" for b in available.values() if b.generators)
        + " (default: the first)",
    )
    options = {}
    for benchmark in available.values():
        for option in benchmark.options:
            options.setdefault(option.flag, []).append(f"{benchmark.name}: {option.help}")
    for flag, helps in sorted(options.items()):
        parser.add_argument(f"--{flag}", type=int, metavar="N", help="; ".join(helps))
    parser.set_defaults(func=run)


def run(args) -> int:
    from ..bench import benchmarks, fresh_seed, progress
    from ..errors import CommandError

    benchmark = benchmarks()[args.name]
    options = {}
    if args.generator is not None:
        if not benchmark.generators:
            raise CommandError(f"{benchmark.name} draws from one generator: --generator does not apply")
        if args.generator not in benchmark.generators:
            raise CommandError(
                f"{benchmark.name} has no generator {args.generator!r}; choose from {', '.join(benchmark.generators)}"
            )
        options["generator"] = args.generator
    for flag in sorted({o.flag for b in benchmarks().values() for o in b.options}):
        value = getattr(args, flag.replace("-", "_"))
        if value is None:
            continue
        if flag not in {o.flag for o in benchmark.options}:
            raise CommandError(f"--{flag} does not apply to {benchmark.name}")
        if value < 0:
            raise CommandError(f"--{flag} must be >= 0, got {value}")
        options[flag.replace("-", "_")] = value
    if benchmark.plots and args.plot_dir:
        options["plot_dir"] = args.plot_dir
    if benchmark.randomised:
        least = 0 if benchmark.options else 1  # a benchmark with trips of other kinds may draw none of these
        if args.count is not None and args.count < least:
            raise CommandError(f"--count must be >= {least}, got {args.count}")
        options["seed"] = fresh_seed() if args.seed is None else args.seed
        options["count"] = args.count
        progress(f"{benchmark.name}: seed {options['seed']} (replay with --seed {options['seed']})")
    elif args.seed is not None or args.count is not None:
        raise CommandError(f"{benchmark.name} is not randomised: --seed and --count do not apply")
    result = benchmark.run(args.quick, **options)
    result = {"benchmark": benchmark.name, "quick": bool(args.quick), **result}
    if benchmark.randomised:
        result["seed"] = options["seed"]
    print(json.dumps(result, allow_nan=True) if args.json else benchmark.render(result))
    return 0
