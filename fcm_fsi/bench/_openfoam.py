"""interFoam (OpenFOAM v1912) side of the peer benchmark: the same cases as ours, run by interFoam.

Library, not a benchmark entry (the leading underscore keeps it off ``python -m fcm_fsi bench``).
interFoam is optional: nothing here is imported by the solver or the tests; callers check
:func:`interfoam_available`, and a case run without it raises RuntimeError.

Cases
    :func:`dam_break_2d`   Martin & Moyce dam break in the closed 6a × 2.5a tank (a = 0.05715 m),
                           one cell thick, all walls slip; the front Z(t) is the wetted length
                           of the bottom, Σ α·Δx over the bottom row of cells (our ∫φ ds).
    :func:`impact_box_3d`  the 3D dam break of ``cases/impact_box_3d.yaml`` onto a fixed box;
                           the force on the box every time step.

Both write an OpenFOAM case into ``workdir`` (dictionaries generated here, numerics of the
tutorial ``multiphase/interFoam/laminar/damBreak``: MULES with vanLeer, PIMPLE with one outer
and three pressure correctors, maxCo = maxAlphaCo = 1), run blockMesh and setFields (and
decomposePar for np > 1), then interFoam, timed on its own. ``workdir`` is the case directory
(a case left there by an earlier call is replaced); the logs stay in it as ``log.<utility>``, and
the per-step series come from function objects under ``postProcessing/`` (reduced over ranks,
so processor directories are not reconstructed).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np

OPENFOAM_DIR = "/usr/share/openfoam"

A_MM = 0.05715
"""Martin & Moyce column width a [m]."""

WATER = {"rho": 998.2, "mu": 1.0e-3}
AIR = {"rho": 1.204, "mu": 1.82e-5}
G = 9.81

HEADER = """FoamFile
{{
    version     2.0;
    format      ascii;
    class       {cls};
    location    "{loc}";
    object      {obj};
}}
"""

WALL_FIELDS = {
    "U": "type slip;",
    "p_rgh": "type fixedFluxPressure; value uniform 0;",
    "alpha.water": "type zeroGradient;",
}
ATMOSPHERE_FIELDS = {
    "U": "type pressureInletOutletVelocity; value uniform (0 0 0);",
    "p_rgh": "type totalPressure; p0 uniform 0;",
    "alpha.water": "type inletOutlet; inletValue uniform 0; value uniform 0;",
}
EMPTY_FIELDS = {name: "type empty;" for name in WALL_FIELDS}

FV_SCHEMES = """ddtSchemes { default Euler; }
gradSchemes { default Gauss linear; }
divSchemes
{
    div(rhoPhi,U)   Gauss linearUpwind grad(U);
    div(phi,alpha)  Gauss vanLeer;
    div(phirb,alpha) Gauss linear;
    div(((rho*nuEff)*dev2(T(grad(U))))) Gauss linear;
}
laplacianSchemes { default Gauss linear corrected; }
interpolationSchemes { default linear; }
snGradSchemes { default corrected; }
"""

FV_SOLUTION = """solvers
{{
    "alpha.water.*"
    {{
        nAlphaCorr      2;
        nAlphaSubCycles 1;
        cAlpha          1;
        MULESCorr       yes;
        nLimiterIter    5;
        solver          smoothSolver;
        smoother        symGaussSeidel;
        tolerance       1e-8;
        relTol          0;
    }}
    "pcorr.*" {{ solver PCG; preconditioner DIC; tolerance 1e-5; relTol 0; }}
    p_rgh {{ solver PCG; preconditioner DIC; tolerance 1e-07; relTol 0.05; }}
    p_rghFinal {{ $p_rgh; relTol 0; }}
    U {{ solver smoothSolver; smoother symGaussSeidel; tolerance 1e-06; relTol 0; }}
}}
PIMPLE
{{
    momentumPredictor   no;
    nOuterCorrectors    1;
    nCorrectors         3;
    nNonOrthogonalCorrectors 0;
{reference}}}
relaxationFactors {{ equations {{ ".*" 1; }} }}
"""


def interfoam_available() -> bool:
    """True when ``interFoam`` is on PATH."""
    return shutil.which("interFoam") is not None


def foam_env(cwd: Path) -> dict:
    """Process environment for the OpenFOAM binaries run in ``cwd`` and OpenMPI (root allowed when root)."""
    env = dict(os.environ, PWD=str(Path(cwd).absolute()))
    env.setdefault("WM_PROJECT_DIR", OPENFOAM_DIR)
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
        env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    return env


def write_dict(case: Path, rel: str, body: str, cls: str = "dictionary") -> None:
    """Write ``case/rel`` as an OpenFOAM dictionary with the standard header."""
    path = case / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(HEADER.format(cls=cls, loc=path.parent.name, obj=path.name) + body)


def foam_vector(v) -> str:
    """OpenFOAM vector text '(x y z)'."""
    return "(" + " ".join(f"{float(c):.10g}" for c in v) + ")"


def clean_case(case: Path) -> None:
    """Remove the outputs of an earlier run of this module from ``case`` (time dirs, mesh, logs)."""
    for p in case.glob("*"):
        is_time = p.is_dir() and p.name.replace(".", "", 1).replace("e-", "", 1).isdigit()
        if is_time or p.name in ("postProcessing", "constant", "system") or p.name.startswith(("processor", "log.")):
            shutil.rmtree(p) if p.is_dir() else p.unlink()


def write_physics(case: Path, gravity) -> None:
    """constant/: g [m/s²], water/air Newtonian (ν = μ/ρ [m²/s]), σ = 0, laminar."""
    write_dict(case, "constant/g", f"dimensions [0 1 -2 0 0 0 0];\nvalue {foam_vector(gravity)};\n",
               cls="uniformDimensionedVectorField")
    phases = "".join(
        f"{name}\n{{\n    transportModel Newtonian;\n    nu {p['mu'] / p['rho']:.10g};\n    rho {p['rho']:.10g};\n}}\n"
        for name, p in (("water", WATER), ("air", AIR)))
    write_dict(case, "constant/transportProperties", f"phases (water air);\n{phases}sigma 0;\n")
    write_dict(case, "constant/turbulenceProperties", "simulationType laminar;\n")


def write_numerics(case: Path, reference: str = "") -> None:
    """system/fvSchemes and fvSolution of the damBreak tutorial; ``reference`` adds pRef entries."""
    write_dict(case, "system/fvSchemes", FV_SCHEMES)
    write_dict(case, "system/fvSolution", FV_SOLUTION.format(reference=reference))


def write_control(case: Path, t_end: float, functions: str) -> None:
    """system/controlDict: Δt₀ = 1 ms, adjustable with maxCo = maxAlphaCo = 1, fields at t_end only."""
    body = f"""application     interFoam;
startFrom       startTime;
startTime       0;
stopAt          endTime;
endTime         {t_end:.10g};
deltaT          0.001;
writeControl    adjustable;
writeInterval   {t_end:.10g};
purgeWrite      0;
writeFormat     ascii;
writePrecision  8;
writeCompression off;
timeFormat      general;
timePrecision   8;
runTimeModifiable no;
adjustTimeStep  yes;
maxCo           1;
maxAlphaCo      1;
maxDeltaT       1;
functions
{{
{functions}}}
"""
    write_dict(case, "system/controlDict", body)


def write_fields(case: Path, patches: dict) -> None:
    """0/U, 0/p_rgh, 0/alpha.water at rest, dry; ``patches`` maps patch name → {field: BC text}."""
    internal = {"U": ("volVectorField", "[0 1 -1 0 0 0 0]", "(0 0 0)"),
                "p_rgh": ("volScalarField", "[1 -1 -2 0 0 0 0]", "0"),
                "alpha.water": ("volScalarField", "[0 0 0 0 0 0 0]", "0")}
    for name, (cls, dims, value) in internal.items():
        bcs = "".join(f"    {patch}\n    {{\n        {bc[name]}\n    }}\n" for patch, bc in patches.items())
        write_dict(case, f"0/{name}", f"dimensions {dims};\ninternalField uniform {value};\n"
                                      f"boundaryField\n{{\n{bcs}}}\n", cls=cls)


def write_set_fields(case: Path, lower, upper) -> None:
    """system/setFieldsDict: α = 1 in cells whose centres lie in the box [lower, upper] [m]."""
    write_dict(case, "system/setFieldsDict", f"""defaultFieldValues ( volScalarFieldValue alpha.water 0 );
regions
(
    boxToCell
    {{
        box {foam_vector(lower)} {foam_vector(upper)};
        fieldValues ( volScalarFieldValue alpha.water 1 );
    }}
);
""")


def write_decompose(case: Path, n) -> None:
    """system/decomposeParDict: simple decomposition into n = (nx ny nz) subdomains."""
    write_dict(case, "system/decomposeParDict", f"""numberOfSubdomains {int(np.prod(n))};
method simple;
coeffs {{ n ({n[0]} {n[1]} {n[2]}); delta 0.001; }}
simpleCoeffs {{ n ({n[0]} {n[1]} {n[2]}); delta 0.001; }}
""")


def run_utility(case: Path, args: list[str], name: str, nproc: int = 1) -> float:
    """Run an OpenFOAM application in ``case`` (under mpirun when nproc > 1), log to log.<name>.

    Returns its wall time [s]; raises RuntimeError with the log's tail when it fails.
    """
    cmd = list(args) + ["-case", str(case)]
    if nproc > 1:
        cmd = ["mpirun", "-n", str(nproc)] + cmd + ["-parallel"]
    log = case / f"log.{name}"
    t0 = time.perf_counter()
    with open(log, "w") as fh:
        rc = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, env=foam_env(case), cwd=case).returncode
    wall = time.perf_counter() - t0
    if rc != 0:
        tail = "".join(log.read_text(errors="replace").splitlines(True)[-30:])
        raise RuntimeError(f"{' '.join(cmd)} failed (exit {rc}); end of {log}:\n{tail}")
    return wall


def count_steps(log: Path) -> int:
    """Number of time steps in an interFoam log (lines starting with 'Time = ')."""
    return sum(1 for line in log.read_text(errors="replace").splitlines() if line.startswith("Time = "))


def read_dat(case: Path, function: str, stem: str) -> np.ndarray:
    """Rows of postProcessing/<function>/0/<stem>.dat as floats (parentheses dropped)."""
    path = case / "postProcessing" / function / "0" / f"{stem}.dat"
    rows = []
    for line in path.read_text().splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            rows.append([float(w) for w in line.replace("(", " ").replace(")", " ").split()])
    return np.array(rows, float)


def prepare_and_run(case: Path, np_: int, decomposition) -> dict:
    """blockMesh, setFields and, for np_ > 1, decomposePar (setup [s]); then interFoam (wall [s], steps)."""
    if not interfoam_available():
        raise RuntimeError("interFoam is not on PATH")
    setup = run_utility(case, ["blockMesh"], "blockMesh")
    setup += run_utility(case, ["setFields"], "setFields")
    if np_ > 1:
        write_decompose(case, decomposition)
        setup += run_utility(case, ["decomposePar", "-force"], "decomposePar")
    wall = run_utility(case, ["interFoam"], "interFoam", nproc=np_)
    return {"wall": wall, "setup": setup, "steps": count_steps(case / "log.interFoam")}


def cell_values(case: Path, rel: str) -> np.ndarray:
    """internalField of a volScalarField file ``case/rel`` as an array (uniform → one value)."""
    words = (case / rel).read_text().split("internalField", 1)[1].split(";", 1)[0]
    if "nonuniform" not in words:
        return np.array([float(words.split()[-1])])
    body = words.split("(", 1)[1].rsplit(")", 1)[0]
    return np.array(body.split(), float)


def mesh_cells(case: Path) -> int:
    """Number of cells from blockMesh's log ('nCells: N')."""
    for line in (case / "log.blockMesh").read_text().splitlines():
        if "nCells:" in line:
            return int(line.split("nCells:")[1].split()[0])
    raise RuntimeError(f"no cell count in {case / 'log.blockMesh'}")


def dam_break_block_mesh(case: Path, cells_x: int, cells_y: int, depth: float) -> None:
    """system/blockMeshDict: the 6a × 2.5a tank [m], cells_x × cells_y × 1 cells, ``depth`` thick."""
    lx, ly = 6 * A_MM, 2.5 * A_MM
    v = [(0, 0, 0), (lx, 0, 0), (lx, ly, 0), (0, ly, 0), (0, 0, depth), (lx, 0, depth), (lx, ly, depth), (0, ly, depth)]
    write_dict(case, "system/blockMeshDict", f"""scale 1;
vertices ( {' '.join(foam_vector(p) for p in v)} );
blocks ( hex (0 1 2 3 4 5 6 7) ({cells_x} {cells_y} 1) simpleGrading (1 1 1) );
edges ( );
boundary
(
    left   {{ type wall; faces ( (0 4 7 3) ); }}
    right  {{ type wall; faces ( (1 2 6 5) ); }}
    bottom {{ type wall; faces ( (0 1 5 4) ); }}
    top    {{ type wall; faces ( (3 7 6 2) ); }}
    frontAndBack {{ type empty; faces ( (0 3 2 1) (4 5 6 7) ); }}
);
mergePatchPairs ( );
""")


BOTTOM_WETTED = """    bottomWetted
    {
        type            surfaceFieldValue;
        libs            ("libfieldFunctionObjects.so");
        writeControl    timeStep;
        writeInterval   1;
        log             false;
        writeFields     false;
        regionType      patch;
        name            bottom;
        operation       areaIntegrate;
        fields          (alpha.water);
    }
"""


def front_history(case: Path, cells_x: int, depth: float) -> tuple[np.ndarray, np.ndarray]:
    """Times t [s] and wetted bottom length [m] = Σ α·Δx of the bottom row, from t = 0 on.

    t = 0 comes from the set-up field 0/alpha.water (the bottom row is the first cells_x cells),
    later times from the ``bottomWetted`` function object (∫ α dA over patch bottom / Δz).
    """
    alpha0 = cell_values(case, "0/alpha.water")
    front0 = alpha0[:cells_x].sum() * depth if alpha0.size > 1 else alpha0[0] * 6 * A_MM
    data = read_dat(case, "bottomWetted", "surfaceFieldValue")
    return np.concatenate(([0.0], data[:, 0])), np.concatenate(([front0], data[:, 1] / depth))


def dam_break_2d(cells_x: int, cells_y: int, workdir: Path, t_end: float, np: int = 1) -> dict:
    """Martin & Moyce dam break (a = 0.05715 m, column a × 2a in a closed 6a × 2.5a tank) by interFoam.

    cells_x × cells_y uniform quads, one cell (Δz = Δx) thick; all walls slip; water/air as in
    our runs, σ = 0, g = 9.81 m/s² along −y; closed tank, p = 0 in the top right cell.
    ``np`` ranks via decomposePar (simple, np × 1 × 1) + mpirun.
    Returns wall [s] of interFoam alone, setup [s] (blockMesh + setFields + decomposePar),
    steps, cells, t [s] and front [m] = ∫_bottom α ds = Σ α·Δx over the bottom row, each step.
    """
    case = Path(workdir)
    case.mkdir(parents=True, exist_ok=True)
    clean_case(case)
    depth = 6 * A_MM / cells_x
    dam_break_block_mesh(case, cells_x, cells_y, depth)
    write_physics(case, (0.0, -G, 0.0))
    corner = foam_vector((6 * A_MM * (1 - 0.5 / cells_x), 2.5 * A_MM * (1 - 0.5 / cells_y), 0.5 * depth))
    write_numerics(case, reference=f"    pRefPoint {corner};\n    pRefValue 0;\n")
    write_control(case, t_end, BOTTOM_WETTED)
    walls = {p: WALL_FIELDS for p in ("left", "right", "bottom", "top")}
    write_fields(case, {**walls, "frontAndBack": EMPTY_FIELDS})
    write_set_fields(case, (-1.0, -1.0, -1.0), (A_MM, 2 * A_MM, 1.0))
    out = prepare_and_run(case, np, (np, 1, 1))
    t, front = front_history(case, cells_x, depth)
    return {**out, "cells": mesh_cells(case), "t": t, "front": front}


def segments(edges, size: float) -> list[int]:
    """Cells per interval between consecutive ``edges`` [m] for a target edge ``size`` [m] (≥ 1)."""
    return [max(1, round((b - a) / size)) for a, b in zip(edges[:-1], edges[1:])]


def impact_block_mesh(case: Path, xs, ys, zs, size: float, solid: tuple) -> None:
    """system/blockMeshDict: the tank cut by planes xs × ys × zs [m] into blocks, block ``solid``
    (i, j, k) left out; its faces form patch ``box``, the top z face ``atmosphere``, the rest ``walls``."""
    nx, ny, nz = segments(xs, size), segments(ys, size), segments(zs, size)

    def vid(i, j, k):
        return i + len(xs) * (j + len(ys) * k)
    verts = [(xs[i], ys[j], zs[k]) for k in range(len(zs)) for j in range(len(ys)) for i in range(len(xs))]
    faces = {  # hex face → (neighbour block offset, outward-ordered local vertices)
        "x-": ((-1, 0, 0), (0, 4, 7, 3)), "x+": ((1, 0, 0), (1, 2, 6, 5)),
        "y-": ((0, -1, 0), (0, 1, 5, 4)), "y+": ((0, 1, 0), (3, 7, 6, 2)),
        "z-": ((0, 0, -1), (0, 3, 2, 1)), "z+": ((0, 0, 1), (4, 5, 6, 7)),
    }
    blocks, patches = [], {"walls": [], "atmosphere": [], "box": []}
    dims = (len(nx), len(ny), len(nz))
    for k in range(dims[2]):
        for j in range(dims[1]):
            for i in range(dims[0]):
                if (i, j, k) == solid:
                    continue
                hv = [vid(i, j, k), vid(i + 1, j, k), vid(i + 1, j + 1, k), vid(i, j + 1, k),
                      vid(i, j, k + 1), vid(i + 1, j, k + 1), vid(i + 1, j + 1, k + 1), vid(i, j + 1, k + 1)]
                blocks.append(f"    hex ({' '.join(map(str, hv))}) ({nx[i]} {ny[j]} {nz[k]}) simpleGrading (1 1 1)")
                for name, (off, local) in faces.items():
                    nb = (i + off[0], j + off[1], k + off[2])
                    face = "(" + " ".join(str(hv[q]) for q in local) + ")"
                    if nb == solid:
                        patches["box"].append(face)
                    elif not all(0 <= nb[d] < dims[d] for d in range(3)):
                        patches["atmosphere" if name == "z+" else "walls"].append(face)
    types = {"walls": "wall", "atmosphere": "patch", "box": "wall"}
    boundary = "".join(f"    {p}\n    {{\n        type {types[p]};\n        faces\n        (\n"
                       + "".join(f"            {f}\n" for f in fs) + "        );\n    }\n"
                       for p, fs in patches.items())
    write_dict(case, "system/blockMeshDict", f"""scale 1;
vertices
(
{''.join(f'    {foam_vector(p)}{chr(10)}' for p in verts)});
blocks
(
{chr(10).join(blocks)}
);
edges ( );
boundary
(
{boundary});
mergePatchPairs ( );
""")


BOX_FORCES = """    boxForces
    {{
        type            forces;
        libs            ("libforces.so");
        writeControl    timeStep;
        writeInterval   1;
        log             false;
        patches         (box);
        rho             rho;
        CofR            {cofr};
    }}
"""


def impact_box_3d(size: float, workdir: Path, t_end: float, np: int = 2) -> dict:
    """3D dam break onto a fixed box, as ``cases/impact_box_3d.yaml``, by interFoam.

    Tank [0, 12] × [−2, 2] × [0, 6] m (z up), water x ≤ 3 m, z ≤ 4 m over the full width, a box
    1 × 1.6 × 2 m on the floor centred at (7, 0, 1) m, removed from the mesh (patch ``box``).
    Hex cells of edge ≈ ``size`` [m], the box faces on cell faces; walls, floor and box slip,
    top open (atmosphere, p = 0). ``np`` ranks via decomposePar (simple, np × 1 × 1) + mpirun.
    Returns wall [s] of interFoam alone, setup [s] (blockMesh + setFields + decomposePar), steps, cells,
    t [s] and force [N] (N × 3, pressure + viscous on the box) each step.
    """
    case = Path(workdir)
    case.mkdir(parents=True, exist_ok=True)
    clean_case(case)
    xs, ys, zs = (0.0, 6.5, 7.5, 12.0), (-2.0, -0.8, 0.8, 2.0), (0.0, 2.0, 6.0)
    impact_block_mesh(case, xs, ys, zs, size, solid=(1, 1, 0))
    write_physics(case, (0.0, 0.0, -G))
    write_numerics(case)
    write_control(case, t_end, BOX_FORCES.format(cofr=foam_vector((7.0, 0.0, 1.0))))
    write_fields(case, {"walls": WALL_FIELDS, "box": WALL_FIELDS, "atmosphere": ATMOSPHERE_FIELDS})
    write_set_fields(case, (-1.0, -3.0, -1.0), (3.0, 3.0, 4.0))
    out = prepare_and_run(case, np, (np, 1, 1))
    data = read_dat(case, "boxForces", "force")
    return {**out, "cells": mesh_cells(case), "t": data[:, 0], "force": data[:, 1:4]}
