"""``povlens plan SCENE --lens LENS [--focus D]``: the render method --method auto chooses."""

from __future__ import annotations

import math
import tempfile

from povlens import api
from povlens.cli.common import print_json
from povlens.cli.render_cmd import add_convert_arguments, convert_keywords, print_notes


def register(sub) -> None:
    p = sub.add_parser("plan", help="choose the render method and samples for a scene (auto)",
                       description="Measure the scene's depth range with a small POV-Ray depth "
                                   "probe and the equivalent thin lens's error over it with the "
                                   "exact tracer, and print the cheapest method within "
                                   "--tolerance (pinhole, focal-blur or mesh), its sample count "
                                   "and the numbers behind the choice.  With -o, OUTDIR is "
                                   "written as by 'convert --method auto' (plan.json records the "
                                   "decision).")
    add_convert_arguments(p)
    for a in p._actions:             # -o is optional here; --method is always auto
        if a.dest == "outdir":
            a.required = False
    p.set_defaults(func=run, method="auto")


def _fmt(v) -> str:
    if isinstance(v, float):
        return "inf" if math.isinf(v) else f"{v:.4g}"
    return str(v)


def run(args) -> int:
    kw = convert_keywords(args) | {"method": "auto"}
    if args.outdir:
        plan = api.convert(args.scene, lens=args.lens, outdir=args.outdir, **kw)
    else:
        with tempfile.TemporaryDirectory(prefix="povlens-plan.") as tmp:
            plan = api.convert(args.scene, lens=args.lens, outdir=tmp, **kw)
    d = plan.decision
    inp = plan.inputs
    print_notes(plan)
    if args.json:
        print_json({"method": d.method, "samples": inp.samples, "focus": inp.focus,
                    "focus_from": inp.focus_from, "decision": d.to_dict(),
                    "outdir": args.outdir})
        return 0
    print(f"{inp.lens}  f/{plan.lens.f_number:.3g}  focus {inp.focus:g} {inp.units} (from "
          f"{inp.focus_from})  {inp.width}x{inp.height}  tolerance {inp.tolerance_px:g} px")
    print(f"method {d.method}, {inp.samples} samples")
    for r in d.reasons:
        print(f"  {r}")
    print("numbers:")
    for k, v in d.numbers.items():
        if isinstance(v, (list, dict)):
            continue
        print(f"  {k:28s} {_fmt(v)}")
    if args.outdir:
        print(f"wrote {api.RenderFolder(args.outdir).plan_json}; render with 'make -C {args.outdir}'")
    return 0
