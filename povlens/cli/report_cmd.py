"""``povlens report OUTDIR... -o report.html``: one self-contained HTML page about render folders."""

from __future__ import annotations

from povlens.errors import UsageError
from povlens.report import DEFAULT_REPORT


def register(sub) -> None:
    p = sub.add_parser(
        "report", help="self-contained HTML report of render folders",
        description="Write one HTML page (every image embedded) about render folders made by "
                    "'povlens convert' or 'povlens render': the lens to scale with ray fans, "
                    "paraxial data and focus, the exit pupil across the field, the depth of "
                    "field over the pinhole render, the renders side by side with differences, "
                    "errors and times against the exact mesh render, and what the thin-lens "
                    "model gets wrong.  Missing renders are shown as 'not rendered'.")
    p.add_argument("outdirs", metavar="OUTDIR", nargs="+", help="render folder(s)")
    p.add_argument("-o", "--output", metavar="HTML", default=DEFAULT_REPORT,
                   help="the page to write (default: %(default)s)")
    p.add_argument("--no-render", action="store_true",
                   help="never run POV-Ray: no missing pinhole/focal-blur views, no depth probe")
    p.set_defaults(func=run)


def run(args) -> int:
    from povlens.report.html import make_report
    if not args.output.lower().endswith((".html", ".htm")):
        raise UsageError(f"-o {args.output}: the report is HTML; name it e.g. report.html")
    path = make_report(args.outdirs, args.output, render_missing=not args.no_render)
    print(path)
    return 0
