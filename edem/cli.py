"""The `edem` command line (README.md#command-line). Exit status 0 success, 1 failed check, 2 bad input."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import textwrap
from pathlib import Path

from geometries.errors import InputError, SolverError
from geometries.extras import MissingExtra, extra_of

#: Default outputs go under ./results, whatever the scene's name (edem.atomic_dirs.default_out_dir).
RESULTS_ROOT = Path("results")


def _run(args: argparse.Namespace) -> int:
    from edem.beds import bed_text
    from edem.pressure_metrics import check_quadrature_size
    from edem.resultdir import provenance
    from edem.results import write_results
    from edem.scene import load_scene, parse_override
    from edem.solver import run

    overrides = dict(parse_override(o) for o in args.set)
    scene = load_scene(args.scene, overrides)
    for warning in scene.warnings:  # said before the solve, so a refused run keeps them
        print(f"edem run: warning: {warning}", file=sys.stderr)
    method = args.method or scene.method
    # the regularised peak of the pressure maps is computed after the solve: refuse a mesh it
    # cannot hold now, not after the solve
    check_quadrature_size(scene.mobile.vertices_mm, scene.mobile.triangles, file=scene.mobile.source or scene.source, key="geometry.mobile")
    out = _out_dir(args, scene.name, method, overrides=overrides)
    record = provenance(args.scene, overrides, method=method)
    n = len(scene.load.time_s)
    bar = _step_bar(n, f"{scene.name} ({method})") if n > 1 and sys.stderr.isatty() else None
    try:
        result = run(scene, method, progress=None if bar is None else (lambda k: bar.update(1)))
    finally:
        if bar is not None:
            bar.close()
    write_results(result, out, overwrite=args.overwrite, provenance=record)
    for warning in result.warnings:
        print(f"edem run: warning: {warning}", file=sys.stderr)
    last = result.steps[-1]
    print("\n".join(result.preflight.lines()))
    print(
        f"{scene.name}: {method.upper()}, {len(result.steps)} time point(s), {result.n_springs} springs, {bed_text(scene.cartilage)}, "
        f"{result.wall_time_s:.3f} s\n"
        f"  peak pressure {max(s.peak_pressure_mpa for s in result.steps):.4g} MPa, "
        f"max contact area {max(s.contact_area_mm2 for s in result.steps):.4g} mm^2, "
        f"final displacement [{', '.join(f'{x:.4g}' for x in last.displacement_mm)}] mm\n"
        f"  results: {out}/ (summary.json, timeseries.csv and .sto, pressure.pvd, fixed.pvd, manifest.json)"
    )
    return 0


def _step_bar(total: int, description: str):
    """A tqdm progress bar of the time points on stderr, or None without tqdm (the `campaigns`
    extra): the bar is a convenience, the run does not need it."""
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc=description, unit="step", file=sys.stderr)


def _print_fe_size(size) -> None:
    """One line before a long FE solve: what it will cost (fem_reference.sizing)."""
    print(f"edem fe: about {size.cells:,} cells, {size.dofs:,} DOFs per solve, {size.solver} linear solver, "
          f"~{size.memory_bytes / 1e9:.2g} GB estimated", file=sys.stderr, flush=True)


def _fe_solve_progress(requested: bool | None, bar):
    """The progress lines from inside each FE solve (fem_reference.progress) on stderr: with
    --progress from the first Newton iteration, by default on a terminal once a solve has run
    a few seconds, never with --no-progress. Written above the step bar when there is one."""
    from fem_reference.progress import TERMINAL_QUIET_S, SolveProgress

    if requested is False or (requested is None and not sys.stderr.isatty()):
        return None
    if bar is not None:
        from tqdm import tqdm

        def write(line: str) -> None:
            tqdm.write(line, file=sys.stderr)
    else:
        def write(line: str) -> None:
            print(line, file=sys.stderr, flush=True)
    return SolveProgress(write, quiet_s=0.0 if requested else TERMINAL_QUIET_S)


def _out_dir(args: argparse.Namespace, *name_parts: str, overrides: dict | None = None) -> Path:
    """--out, or results/<scene>-<method>[-set-<hash of the overrides>], checked before any solve."""
    from edem.atomic_dirs import check_out_dir, default_out_dir

    out = Path(args.out) if args.out else default_out_dir(RESULTS_ROOT, *name_parts, overrides=overrides)
    return check_out_dir(out, overwrite=args.overwrite)


def _fe(args: argparse.Namespace) -> int:
    """The FE reference of a scene (docs/method.md#6-the-fe-reference-and-its-discrete-twins, docs/result-format.md): fem_reference.run_scene into a result directory."""
    from edem.resultdir import provenance
    from edem.scene import load_scene, parse_override

    try:
        from fem_reference.scene_run import run_scene, world_rank
        from fem_reference.settings import resolve_settings
    except ImportError as exc:
        raise InputError(f"the FE reference is not available ({exc})", expected="the `fe` extra: pip install -e '.[fe]'") from None
    rank = world_rank()  # under mpirun every rank runs this; rank 0 alone reports
    bar = None
    try:
        overrides = dict(parse_override(o) for o in args.set)
        scene = load_scene(args.scene, overrides)
        settings = resolve_settings(scene, model=args.model, mesh_size_mm=args.mesh_size, degree=args.degree,
                                    linear_solver=args.linear_solver, contact_mesh_size_mm=args.contact_mesh_size, argument_keys=FE_FLAGS)
        steps = parse_steps(args.steps, len(scene.load.time_s))
        out = _out_dir(args, scene.name, settings.method, overrides=overrides)
        record = provenance(args.scene, overrides, {"model": settings.model, "mesh_size_mm": settings.mesh_size_mm, "degree": settings.degree,
                                                        "linear_solver": settings.linear_solver,
                                                        "contact_mesh_size_mm": settings.contact_mesh_size_mm})
        n_solves = len(scene.load.time_s) if steps is None else len(steps)
        if rank == 0 and n_solves > 1 and sys.stderr.isatty():
            bar = _step_bar(n_solves, f"{scene.name} ({settings.method})")
        result = run_scene(scene, model=settings.model, mesh_size_mm=args.mesh_size, degree=args.degree,
                           linear_solver=args.linear_solver, contact_mesh_size_mm=args.contact_mesh_size, steps=steps, out_dir=out,
                           overwrite=args.overwrite, provenance=record, progress=None if bar is None else (lambda k: bar.update(1)),
                           on_size=_print_fe_size if rank == 0 else None,
                           solve_progress=_fe_solve_progress(args.progress, bar) if rank == 0 else None)
    except (InputError, SolverError):
        if rank != 0:  # every rank fails alike: rank 0 alone reports it
            return 2
        raise
    finally:
        if bar is not None:
            bar.close()
    if rank != 0:
        return 0
    for warning in result.warnings:
        print(f"edem fe: warning: {warning}", file=sys.stderr)
    data = result.summary()
    krylov = f" ({data['krylov_iterations']} Krylov iterations)" if "iterative" in data["linear_solver"] else ""
    print(
        f"{scene.name}: FE {settings.model} ({data['element']}, mesh {settings.mesh_size_mm:g} mm), {data['steps']} time point(s), "
        f"{data['n_dofs']} DOFs, {data['newton_iterations']} Newton iterations{krylov}, {result.wall_time_s:.3f} s\n"
        f"  peak pressure {data['peak_pressure_mpa']:.4g} MPa, max contact area {data['max_contact_area_mm2']:.4g} mm^2, "
        f"final displacement [{', '.join(f'{x:.4g}' for x in data['final_displacement_mm'])}] mm\n"
        f"  results: {out}/ (summary.json, timeseries.csv, pressure.pvd)"
    )
    return 0


#: the `edem fe` flag of each resolve_settings argument (errors name what the user typed)
FE_FLAGS = {"model": "--model", "mesh_size_mm": "--mesh-size", "degree": "--degree", "linear_solver": "--linear-solver",
            "contact_mesh_size_mm": "--contact-mesh-size"}


def parse_steps(text: str | None, n: int) -> list[int] | None:
    """``--steps``: None = all; text "0,3,5-9,10:65:8" (a-b inclusive, a:b[:c] as Python slices;
    negative indices count from the end) of a scene with n time points. Sorted, unique."""
    if text is None:
        return None
    out: list[int] = []
    expected = f"time point indices 0..{n - 1}: a comma list of N, A-B (inclusive) or A:B[:STEP]"
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        try:
            if ":" in part:
                bits = [int(b) if b.strip() else None for b in part.split(":")]
                if len(bits) > 3:
                    raise ValueError
                out += list(range(n))[slice(*bits)]
            elif "-" in part[1:]:
                i = part.index("-", 1)
                a, b = int(part[:i]), int(part[i + 1:])
                if b < a:
                    raise ValueError
                out += list(range(a, b + 1))
            else:
                out.append(int(part))
        except ValueError:
            raise InputError(f"cannot read the time point selection '{part}'", key="--steps", expected=expected) from None
    selected = {i + n if i < 0 else i for i in out}
    outside = [i for i in out if not 0 <= (i + n if i < 0 else i) < n]
    if outside:
        raise InputError(f"time point {outside[0]} does not exist (the scene has {n})", key="--steps", expected=expected)
    if not selected:
        raise InputError("the time point selection is empty", key="--steps", expected=expected)
    return sorted(selected)


def _scenes(args: argparse.Namespace) -> int:
    from edem.scene import builtin_scene_names, resolve_scene_path

    names = builtin_scene_names()
    if args.render:
        from reports.scene_renders import render_scene_pngs

        for path in render_scene_pngs(names, args.render):
            print(path)
        return 0
    if args.write:
        target = Path(args.write)
        target.mkdir(parents=True, exist_ok=True)
        for name in names:
            (target / f"{name}.toml").write_text(resolve_scene_path(name).read_text(encoding="utf-8"), encoding="utf-8")
        print(f"wrote {len(names)} scene files to {target}/")
        return 0
    import tomllib

    for name in names:
        data = tomllib.loads(resolve_scene_path(name).read_text(encoding="utf-8"))
        description = " ".join(data.get("scene", {}).get("description", "").split())  # the whole description, rewrapped
        print(textwrap.fill(f"{name:24s} {description}", width=110, subsequent_indent=" " * 25, break_on_hyphens=False, break_long_words=False) + "\n")
    return 0


def _plot(args: argparse.Namespace) -> int:
    from reports.plots import plot_timeseries

    print(plot_timeseries(args.result_dirs, args.column, args.out, args.label))
    return 0


def _compare(args: argparse.Namespace) -> int:
    """The comparison metrics (docs/method.md#7-comparison-metrics) of result directory A against the reference B; writes metrics.json."""
    from edem.atomic_dirs import check_out_dir, default_out_dir
    from verification.metrics import compare_result_dirs, format_metrics_table
    from verification.runner import write_json

    out = Path(args.out) if args.out else default_out_dir(RESULTS_ROOT / "compare", Path(args.a_dir).name, "vs", Path(args.b_dir).name)
    out = check_out_dir(out, reuse_if=("metrics.json",))
    comparison = compare_result_dirs(args.a_dir, args.b_dir)
    write_json(out / "metrics.json", comparison)
    print(format_metrics_table(comparison))
    if args.maps:
        from reports.maps import render_pressure_maps

        print(f"pressure maps: {render_pressure_maps(args.a_dir, args.b_dir, out / 'pressure_maps.png')}")
    print(f"metrics: {out / 'metrics.json'}")
    return 0


def _verify(args: argparse.Namespace) -> int:
    """Run a verification campaign (or list them); exit 1 when a case fails its tolerance."""
    from verification.campaigns import describe_campaigns, get_campaign

    if args.list:
        print(describe_campaigns(args.campaign), end="")
        return 0
    if not args.campaign:
        raise InputError("no campaign given", key="CAMPAIGN", expected="a campaign name (edem verify --list)")
    from edem.atomic_dirs import check_out_dir
    from reports.html import write_campaign_report
    from verification.runner import format_summary, run_campaign

    from verification.campaigns import DATA_CAMPAIGNS

    # refused (exit 2: an unknown name, --data missing, wrong or not wanted) before the output is made
    if args.campaign in DATA_CAMPAIGNS:
        DATA_CAMPAIGNS[args.campaign].data_files(args.data)
    else:
        campaign = get_campaign(args.campaign)
        if args.data is not None:
            get_campaign(args.campaign, args.data)  # refused: this campaign takes no data folder
    if args.refresh_reference and args.campaign != "fe-convergence":
        raise InputError(f"--refresh-reference with campaign '{args.campaign}'", key="--refresh-reference", expected="edem verify fe-convergence --refresh-reference")
    out = check_out_dir(Path(args.out) if args.out else RESULTS_ROOT / "verify" / args.campaign, reuse_if=("cases", ".lock"))
    if args.campaign in DATA_CAMPAIGNS:
        campaign = get_campaign(args.campaign, args.data, out / "inputs")
    summary = run_campaign(campaign, out, jobs=args.jobs, scheduler=args.scheduler, report=write_campaign_report)
    print(format_summary(summary))
    print(f"report: {summary['report']}")
    if args.refresh_reference:
        from verification.fe_convergence import write_reference

        print(f"FE errors stored: {write_reference(summary)}")
    return summary["exit_status"]


def _check(args: argparse.Namespace) -> int:
    """`edem check`: the regression gate (README.md#command-line)."""
    from verification.check import run_check

    return run_check(refresh=args.refresh, references=args.references, with_fe=not args.no_fe)


class _VersionAction(argparse.Action):
    """``--version``: the package version and the git revision, computed only when asked (keeps --help fast)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from edem.resultdir import software_version, source_revision

        print(f"edem {software_version()} (source {source_revision()})")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="edem", description="Discrete-element (DEM/EDEM) joint contact solver.")
    parser.add_argument("--version", action=_VersionAction, help="print the version and the source revision, then exit")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("run", help="solve a scene with the discrete method")
    p.add_argument("scene", help="a scene TOML file or the name of a built-in scene (edem scenes)")
    p.add_argument("--method", choices=("edem", "dem"), help="overrides [solver] method")
    p.add_argument("--out", help="result directory (default results/<scene>-<method>, plus -set-<hash> with --set)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing result directory (never another kind of directory)")
    p.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="override a scene value, e.g. --set cartilage.poissons_ratio=0.3"
    )
    p.set_defaults(func=_run)
    p = sub.add_parser("fe", help="solve the FE reference (dolfinx) of a scene")
    p.add_argument("scene", help="a scene TOML file or the name of a built-in scene (edem scenes)")
    p.add_argument("--model", help="an FE model (fem_reference.models): slab (twin of the threshold law), layer (of the gap laws, F rigid), two-layer (both "
                   "layers deformable) or lumped (both layers summed into one on M, F's bone rigid); overrides [fe] model")
    p.add_argument("--out", help="result directory (default results/<scene>-fe-<model>, plus -set-<hash> with --set)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing result directory (never another kind of directory)")
    p.add_argument("--mesh-size", type=float, metavar="MM", help="element size in mm; overrides [fe] mesh_size_mm")
    p.add_argument("--contact-mesh-size", type=float, metavar="MM",
                   help="a finer element size in mm where the contact can reach (the layer models; red-green transition around it); "
                        "overrides [fe] contact_mesh_size_mm")
    p.add_argument("--degree", type=int, choices=(1, 2), help="element degree (2: P2, or Taylor-Hood at nu >= 0.49); overrides [fe] degree")
    p.add_argument("--linear-solver", metavar="NAME",
                   help="inner linear solve: auto (Krylov from 20,000 unknowns for P2 and Taylor-Hood, or where the LU does not fit in memory, MUMPS LU below), direct or iterative "
                        "(docs/method.md, section 6); overrides [fe] linear_solver")
    p.add_argument("--steps", metavar="LIST", help="time points to solve, e.g. 0,5-9,10:65:8 (default: all)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="lines from inside each solve on stderr (Newton residual, contact nodes, Krylov iterations); "
                        "default: on a terminal, once a solve has run a few seconds")
    p.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="override a scene value, e.g. --set cartilage.poissons_ratio=0.3"
    )
    p.set_defaults(func=_fe)
    p = sub.add_parser("scenes", help="list the built-in scenes")
    p.add_argument("--write", metavar="DIR", help="write their TOML files to DIR for editing")
    p.add_argument("--render", metavar="DIR", help="render each scene's geometry to DIR/<scene>.png (pyvista, off-screen)")
    p.set_defaults(func=_scenes)
    p = sub.add_parser("plot", help="plot a timeseries.csv column of result directories against time")
    p.add_argument("result_dirs", nargs="+", help="result directories of edem run")
    p.add_argument("--column", default="disp_norm_mm", help="a timeseries.csv column, or disp_norm_mm (default)")
    p.add_argument("--label", action="append", help="legend label per directory (repeat)")
    p.add_argument("--out", help="PNG file to write (default: beside the first directory, <dir>-<column>.png or <dir>-vs-<other dirs>-<column>.png)")
    p.set_defaults(func=_plot)
    p = sub.add_parser("compare", help="comparison metrics between two result directories (B is the reference; docs/method.md#7-comparison-metrics)")
    p.add_argument("a_dir", metavar="A_DIR", help="result directory of the method under test (edem run)")
    p.add_argument("b_dir", metavar="B_DIR", help="result directory of the reference (edem fe, or another run)")
    p.add_argument("--out", help="where metrics.json goes (default results/compare/<A>-vs-<B>)")
    p.add_argument("--maps", action="store_true", help="also render pressure maps of A, B and A - B (pyvista, off-screen)")
    p.set_defaults(func=_compare)
    p = sub.add_parser("verify", help="run a verification campaign, ending in an HTML report")
    p.add_argument("campaign", nargs="?", metavar="CAMPAIGN", help="a campaign name (see --list)")
    p.add_argument("--list", action="store_true", help="list the campaigns (one line each, with case count and expected time); with CAMPAIGN, its cases")
    p.add_argument("--out", help="output directory (default results/verify/<campaign>); finished cases are cached there")
    p.add_argument("--jobs", type=int, help="worker processes (default: the CPU count; 1 runs in this process)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run the cases on a Dask distributed cluster, e.g. tcp://host:8786")
    p.add_argument("--data", metavar="FOLDER", help="the public data a campaign runs on (real-knee: the Lenhart knee folder, docs/campaigns.md#real-knee-dem-against-the-fe-on-a-real-knee)")
    p.add_argument("--refresh-reference", action="store_true",
                   help="with fe-convergence: store the FE errors it estimates in verification/references/fe_convergence.json, where the other campaigns' FE references find them")
    p.set_defaults(func=_verify)
    p = sub.add_parser("check", help="regression gate: rerun EDEM on stored references, exit 1 with a table when something drifted")
    p.add_argument("--refresh", action="store_true", help="recompute the stored references (FE values too when the FE reference is available)")
    p.add_argument("--references", metavar="DIR", help="reference directory (default verification/references/)")
    p.add_argument("--no-fe", action="store_true", help="with --refresh: store EDEM baselines only")
    p.set_defaults(func=_check)
    return parser


class _CtrlC:
    """SIGINT handler that remembers it fired. A Ctrl-C can surface as another exception: inside
    an import, VTK's module loader turns the KeyboardInterrupt into an ImportError."""

    fired = False

    def __call__(self, signum, frame):
        self.fired = True
        raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    """Run the command line (``argv=None``: sys.argv). Exit status as in the module docstring;
    130 after Ctrl-C."""
    args = build_parser().parse_args(argv)
    # Before numpy loads: one BLAS thread per process. The solver's dense kernels are small (6 x 6,
    # the coupled layer's banded Cholesky), campaigns run one process per core, and OpenBLAS
    # threads that find their core busy spin: the banded factorisation then took 50-580 ms
    # instead of 16 ms on this project's 2-core machine. A value the user set is kept.
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    ctrl_c = _CtrlC()
    previous = signal.getsignal(signal.SIGINT)
    if previous is signal.default_int_handler:  # not when SIGINT is ignored (a campaign worker)
        signal.signal(signal.SIGINT, ctrl_c)
    try:
        return args.func(args)
    except InputError as exc:
        print(f"edem {args.command}: bad input: {exc}", file=sys.stderr)
        return 2
    except SolverError as exc:
        print(f"edem {args.command}: no solution: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # Ctrl-C: no traceback; campaigns say what they kept
        print(f"edem {args.command}: {str(exc) or 'interrupted'}", file=sys.stderr)
        return 130
    except Exception as exc:
        if ctrl_c.fired:
            print(f"edem {args.command}: interrupted", file=sys.stderr)
            return 130
        if isinstance(exc, ImportError) and extra_of(exc) is not None:  # an optional part not installed
            print(f"edem {args.command}: bad input: {MissingExtra(exc.name.split('.')[0], extra_of(exc), f'edem {args.command}')}",
                  file=sys.stderr)
            return 2
        if isinstance(exc, OSError):  # disk full or not writable where no finer message was given
            print(f"edem {args.command}: cannot write: {exc}", file=sys.stderr)
            return 2
        raise
    finally:
        signal.signal(signal.SIGINT, previous)


def console_main() -> int:
    """The ``edem`` command (and ``python -m edem``): :func:`main`, then Ctrl-C ignored while the
    interpreter exits. By then the result is written whole or not at all; but at exit Python
    resets a Python-level SIGINT handler to the default action, so a Ctrl-C in the 0.1-0.2 s of
    unloading numpy, scipy and VTK killed a finished run (status -2, nothing printed) instead of
    letting it exit with its own status. :func:`main` itself restores the caller's handler (it
    is also called in-process)."""
    status = main()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    return status


if __name__ == "__main__":
    sys.exit(console_main())
