"""``layerstack design DESIGN.toml -o design.toml [--plot design.png]``."""

from __future__ import annotations

from pathlib import Path

from ._common import PROG, _precision

def _add_design_parser(sub) -> None:
    p = sub.add_parser(
        "design",
        help="optimise layer thicknesses of a stack towards spectral and colour targets",
        description="Optimise the layer thicknesses marked free in a design file (a stack file with "
        "thickness_nm = { value = 100, free = true, min = 0, max = 400 }, [[targets]], [optimizer] and "
        "[robustness] tables; format: see fitting._design_file and layerstack_jax.io) and write the designed stack as a stack file "
        "(readable by `layerstack predict`) whose header comments state the merit before and after, every "
        "target's result and the yield. Exit status 0 when every target is met (and the yield reaches "
        "min_yield), 1 when not, 2 for a bad input.",
    )
    p.add_argument("design", metavar="DESIGN.toml", help="design file (format: see fitting._design_file and layerstack_jax.io)")
    p.add_argument("--output", "-o", required=True, metavar="OUT.toml", help="designed stack file to write")
    p.add_argument("--plot", metavar="OUT.png", help="also plot the targets against the design (PNG)")
    p.add_argument("--float32", action="store_true", help="compute in float32 (default: float64)")
    p.set_defaults(func=_cmd_design)


def _cmd_design(args) -> int:
    from datetime import datetime

    from layerstack_jax.io import save_stack

    with _precision(args.float32):
        from fitting import design_report, design_stack_dict, load_design, plot_design, run_design

        design = load_design(args.design)
        outcome = run_design(design)
        report = design_report(outcome)
        out = Path(args.output)
        stamp = datetime.now().isoformat(timespec="seconds")
        header = "\n".join([f"Designed by `layerstack design {args.design}` on {stamp}.", *report])
        save_stack(out, design_stack_dict(outcome, out.parent), header=header)
        print("\n".join(report))
        n = len(outcome.stack.layers)
        print(f"{PROG}: wrote {out} ({n} layer{'' if n == 1 else 's'}) in {outcome.seconds:.1f} s")
        if args.plot:
            plot = plot_design(outcome, args.plot)
            print(f"{PROG}: wrote {plot} (targets vs design)")
    return 0 if outcome.met else 1


