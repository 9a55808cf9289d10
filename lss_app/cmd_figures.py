"""`lss figures`: the figures and tables of the documents that are computed
rather than drawn from a run (docs/contact_laws.md)."""
from __future__ import annotations

from pathlib import Path


def register(sub, common) -> None:
    from .figures.contact_laws import FIG_DIR
    ap = sub.add_parser("figures", parents=[common], help="figures and tables of the documents")
    fsub = ap.add_subparsers(dest="which", required=True, metavar="WHICH")
    cl = fsub.add_parser("contact-laws", help="restitution of the damping laws (docs/contact_laws.md)")
    cl.add_argument("--out", type=Path, default=FIG_DIR, help="figure folder (default docs/figures)")
    cl.add_argument("--table", action="store_true", help="print the tables as Markdown")
    cl.add_argument("--no-figures", action="store_true")
    cl.set_defaults(run=run_contact_laws)


def run_contact_laws(args) -> int:
    from .figures.contact_laws import accuracy, make_figures, tables
    if not args.no_figures:
        for p in make_figures(args.out):
            print("wrote", p)
    print(tables(markdown=args.table))
    print()
    print("max |e_eff - e_pred| over the grid (mean accepted steps per impact)")
    print(accuracy(markdown=args.table))
    return 0
