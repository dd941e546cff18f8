"""The Hertz benchmark: gmsh meshes of a quarter sphere resting on a quarter block, and the analytical solution.

Quarter model (symmetry planes x = 0 and y = 0) of an elastic sphere of radius R, cut at its
equator (flat top face at z = R), touching an elastic block [0, L] x [0, L] x [-H, 0] at the
origin. Both bodies are refined around the contact point, with different sizes on the two
contact surfaces, so that the meshes do not match there. Lengths scale with R; the sizes below
are for a contact radius a of about 0.1 R (the loads of configs/hertz_*.toml).

Why these dimensions: Hertz theory treats both bodies as half-spaces near the contact, so every
other dimension must be large against a. The sphere's top is R = 10 a above the contact and the
block is L = H = 2 R = 20 a wide and deep (the half-space displacement decays like a / r).
Measured (medium level, two_pass with Gauss points): a block of 4 R instead of 2 R changes the
force by 1.1 %, and at the measured force the fitted peak pressure by at most 1.2 % and the contact
radius by 0.4 %; the comparison with Hertz is made at the measured force for that reason.
The contact surfaces ("contact" on both parts) are the sphere's cap and the block's top within
CONTACT_ZONE R of the axis (1.5 a): every node that can touch is on them, and their mean face
size, which sets the penalty and the search distance, is the refined size.

Meshes are written once per (part, level, R) into a cache folder and reused; the file name
carries a hash of the generator parameters, so a changed generator never reuses an old file.
"""

import hashlib
import json
import math
import os
from pathlib import Path

import numpy as np

from . import fem
from .errors import MeshError

PARTS = ("sphere", "block")
LEVELS = ("coarse", "medium", "fine", "xfine")
CONTACT_ZONE = 0.15        # radius of the contact surfaces, in units of R
BLOCK_SIZE = 2.0           # block width L and depth H, in units of R
# Element size on the contact surfaces, in units of R, per level: (sphere, block). The block is
# 1.4x coarser, so the two surfaces never match; a is about 0.1 R, so coarse has 4 sphere
# elements across the contact radius, fine 16, xfine 32 (each level halves the sizes of the one before).
SIZES = {"coarse": (0.025, 0.035), "medium": (0.0125, 0.0175), "fine": (0.00625, 0.00875),
         "xfine": (0.003125, 0.004375)}
FAR_SIZE = {"sphere": 0.2, "block": 0.5}   # element size far from the contact, in units of R
GROWTH = 0.35              # the size grows by this much per unit distance beyond the zone (relative to R)
GENERATOR_VERSION = 1      # bump when the geometry or the meshing changes
TOL = 1e-5                 # relative tolerance of geometric tests at R = 1 (gmsh pads bounding boxes by 1e-7)


# ---------------------------------------------------------------- analytical solution (pure NumPy)

def effective_modulus(E1, nu1, E2, nu2):
    """Contact modulus E* [Pa] of two elastic bodies: 1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2."""
    return 1.0 / ((1.0 - nu1 ** 2) / E1 + (1.0 - nu2 ** 2) / E2)


def contact_radius(F, R, E_star):
    """Hertz contact radius a [m] of a sphere of radius R [m] on a half-space under the total force F [N]."""
    return (3.0 * F * R / (4.0 * E_star)) ** (1.0 / 3.0)


def peak_pressure(F, a):
    """Hertz peak pressure p0 = 3 F / (2 pi a^2) [Pa]."""
    return 3.0 * F / (2.0 * math.pi * a ** 2)


def pressure(r, a, p0):
    """Hertz pressure p(r) = p0 sqrt(1 - r^2/a^2) inside the contact radius, 0 outside [Pa]."""
    r = np.asarray(r, dtype=float)
    return p0 * np.sqrt(np.clip(1.0 - (r / a) ** 2, 0.0, None))


def loaded_radius(r, t, fraction=0.01):
    """Radius where the nodal traction drops to zero: the circle that best separates loaded nodes
    (t > fraction * max t) from the others, i.e. the cut of the sorted radii that misclassifies the
    fewest nodes, placed midway between the two nodes it falls between. Returns (radius, misclassified)."""
    r, t = np.asarray(r, float), np.asarray(t, float)
    order = np.argsort(r)
    r, loaded = r[order], t[order] > fraction * t.max()
    # errors of the cut before sorted position i: unloaded nodes inside + loaded nodes outside
    errors = np.r_[0, np.cumsum(~loaded)] + np.r_[loaded.sum(), loaded.sum() - np.cumsum(loaded)]
    i = int(np.argmin(errors))
    if i == 0 or i == len(r):
        return (r[0] if i == 0 else r[-1]), int(errors[i])
    return 0.5 * (r[i - 1] + r[i]), int(errors[i])


def centre_fit(r, t, radius):
    """Traction at r = 0 from a least-squares fit t = c0 + c2 r^2 over the nodes with r < radius
    (filters the node-to-node scatter of nodal tractions; Hertz's r^4 term biases c0 by < 0.3 % for
    radius = a/2). Returns c0."""
    r, t = np.asarray(r, float), np.asarray(t, float)
    near = r < radius
    A = np.column_stack([np.ones(near.sum()), r[near] ** 2])
    return float(np.linalg.lstsq(A, t[near], rcond=None)[0][0])


def lumped_traction(points, faces, pressure_field, n_gauss=6):
    """Nodal traction F_k / A_k [Pa] of a given pressure field on triangles faces (m, 3) of points (n, 3): the
    consistent nodal force int N_k p ds over the lumped area int N_k ds, the measure of the product's
    contact_traction output. NaN off the faces. pressure_field: function of points (q, 3) -> (q,) [Pa]."""
    xf = points[faces]
    force = np.abs(fem.face_pressure_loads("tri", xf, pressure_field, n_gauss)[..., 2])
    area = fem.face_nodal_areas("tri", xf)
    F, A = np.zeros(len(points)), np.zeros(len(points))
    np.add.at(F, faces, force)
    np.add.at(A, faces, area)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(A > 0, F / A, np.nan)


def traction_scatter(points, faces, traction, a, p0, band=0.5):
    """Where the nodal traction t of one contact surface departs from Hertz's p(r), within r < band * a.

    Nodes on a symmetry plane (x = 0 or y = 0, the origin excepted: it lies on both planes with a quarter
    patch and reads apart) and the others are taken apart, because a mesh conforming to a plane across the
    contact carries a band there (nodes on the plane high, the next row low). Returns t / p(r) on the plane
    nodes (edge_mean), on the off-plane nodes within one mean face size h of a plane (row_mean) and on all
    off-plane nodes (interior_mean, interior_std, interior_max); t / p0 at the origin node (origin, NaN
    without one) and the largest t / p0 off the planes (interior_peak); and exact_error: the largest
    |F_k/A_k / p(r_k) - 1| of the measure itself applied to the exact Hertz pressure (lumped_traction) on
    the same nodes."""
    faces = np.asarray(faces)
    v = np.unique(faces)
    r = np.hypot(points[v, 0], points[v, 1])
    v, r = v[r < band * a], r[r < band * a]
    pH = pressure(r, a, p0)
    t = np.asarray(traction, float)[v]
    q = t / pH
    xf = points[faces]
    tol = TOL * max(float(np.abs(xf).max()), 1e-300)
    h = fem.face_size(xf)[np.hypot(*xf.mean(axis=1)[:, :2].T) < band * a].mean()
    d = np.minimum(np.abs(points[v, 0]), np.abs(points[v, 1]))        # distance to the nearer plane
    axis = r < tol
    edge = (d < tol) & ~axis
    off = d >= tol
    row = off & (d < h)
    exact = lumped_traction(points, faces, lambda x: pressure(np.hypot(x[:, 0], x[:, 1]), a, p0))[v] / pH

    def mean(m):
        return float(q[m].mean()) if m.any() else float("nan")
    return {"edge_mean": mean(edge), "row_mean": mean(row), "interior_mean": mean(off),
            "interior_std": float(q[off].std()), "interior_max": float(q[off].max()),
            "origin": float(t[axis][0] / p0) if axis.any() else float("nan"),
            "interior_peak": float(t[off].max() / p0), "exact_error": float(np.abs(exact - 1.0).max())}


# ---------------------------------------------------------------- meshes

def parameters(part, level, radius):
    """Everything that decides a mesh, as a dict (also hashed into the cache file name)."""
    if part not in PARTS:
        raise MeshError(f"hertz mesh: part must be one of {', '.join(PARTS)}, got {part!r}")
    if level not in LEVELS:
        raise MeshError(f"hertz mesh: level must be one of {', '.join(LEVELS)}, got {level!r}")
    size = SIZES[level][PARTS.index(part)]
    return {"version": GENERATOR_VERSION, "part": part, "level": level, "radius": float(radius),
            "zone": CONTACT_ZONE, "block": BLOCK_SIZE, "size": size, "far": FAR_SIZE[part], "growth": GROWTH}


def mesh_path(part, level, radius, cache):
    """The cache file of a part: <cache>/hertz_<part>_<level>_<hash>.msh."""
    params = parameters(part, level, radius)
    digest = hashlib.sha1(json.dumps(params, sort_keys=True).encode()).hexdigest()[:10]
    return Path(cache) / f"hertz_{part}_{level}_{digest}.msh"


def mesh_file(part, level, radius=1.0, cache="build/meshes"):
    """Path of the part's .msh file, generated with gmsh if it is not in the cache yet."""
    path = mesh_path(part, level, radius, cache)
    if not path.is_file():
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise MeshError(f"hertz mesh: cannot create the cache folder {str(path.parent)!r}: {exc.strerror}") from None
        tmp = path.with_suffix(f".{os.getpid()}.msh")
        write_mesh(parameters(part, level, radius), tmp)
        os.replace(tmp, path)        # atomic: a concurrent run sees no half-written file
    return path


def _size_field(gmsh, R, p):
    """Size = p["size"] R within the zone, growing linearly with the distance to the contact point."""
    f = gmsh.model.mesh.field
    ball = f.add("MathEval")
    zone, h, far, growth = p["zone"] * R, p["size"] * R, p["far"] * R, p["growth"]
    r = "Sqrt(x*x + y*y + z*z)"
    f.setString(ball, "F", f"Min({far}, {h} + {growth} * Max(0, {r} - {zone}))")
    f.setAsBackgroundMesh(ball)
    for option in ("MeshSizeExtendFromBoundary", "MeshSizeFromPoints", "MeshSizeFromCurvature"):
        gmsh.option.setNumber(f"Mesh.{option}", 0)


def _sphere(gmsh, R, p):
    """Quarter of the lower half of the ball of radius R centred (0, 0, R); cap |r| < zone split off."""
    occ = gmsh.model.occ
    ball = occ.addSphere(0, 0, R, R)
    box = occ.addBox(0, 0, 0, R, R, R)
    (quarter, _) = occ.intersect([(3, ball)], [(3, box)])
    zone = p["zone"] * R
    zc = R - math.sqrt(R * R - zone * zone)
    cutter = occ.addBox(0, 0, 0, R, R, zc)
    occ.fragment(quarter, [(3, cutter)])
    occ.synchronize()
    vols = gmsh.model.getEntities(3)
    # pieces of the cutter box outside the ball: volumes whose centre is outside the ball
    for dim, tag in vols:
        c = occ.getCenterOfMass(dim, tag)
        if math.dist(c, (0, 0, R)) > R:
            occ.remove([(dim, tag)], recursive=True)
    occ.synchronize()
    return _groups_sphere(gmsh, R, zc)


def _groups_sphere(gmsh, R, zc):
    groups = {"xmin": [], "ymin": [], "top": [], "contact": [], "outer": []}
    tol = TOL * R
    for _, tag in gmsh.model.getEntities(2):
        x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, tag)
        if x1 - x0 < tol and abs(x0) < tol:
            groups["xmin"].append(tag)
        elif y1 - y0 < tol and abs(y0) < tol:
            groups["ymin"].append(tag)
        elif z1 - z0 < tol:                  # the top face z = R, or the internal cut z = zc
            if abs(z0 - R) < tol:
                groups["top"].append(tag)
        else:
            groups["contact" if z1 <= zc + tol else "outer"].append(tag)
    return groups


def _block(gmsh, R, p):
    """The block [0, L] x [0, L] x [-H, 0] with the quarter disk r < zone split off its top face."""
    occ = gmsh.model.occ
    L = p["block"] * R
    zone = p["zone"] * R
    box = occ.addBox(0, 0, -L, L, L, L)
    cyl = occ.addCylinder(0, 0, -zone, 0, 0, zone, zone)
    occ.fragment([(3, box)], [(3, cyl)])
    occ.synchronize()
    for dim, tag in gmsh.model.getEntities(3):
        c = occ.getCenterOfMass(dim, tag)
        if c[0] < 0 or c[1] < 0:
            occ.remove([(dim, tag)], recursive=True)
    occ.synchronize()
    groups = {"xmin": [], "ymin": [], "zmin": [], "xmax": [], "ymax": [], "contact": [], "top": []}
    for _, tag in gmsh.model.getEntities(2):
        x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, tag)
        tol = TOL * R
        if x1 - x0 < tol and abs(x0) < tol:
            groups["xmin"].append(tag)
        elif y1 - y0 < tol and abs(y0) < tol:
            groups["ymin"].append(tag)
        elif x1 - x0 < tol and abs(x0 - L) < tol:
            groups["xmax"].append(tag)
        elif y1 - y0 < tol and abs(y0 - L) < tol:
            groups["ymax"].append(tag)
        elif z1 - z0 < tol and abs(z0 + L) < tol:
            groups["zmin"].append(tag)
        elif z1 - z0 < tol and abs(z0) < tol:
            groups["contact" if x1 <= zone + tol and y1 <= zone + tol else "top"].append(tag)
    return groups


def write_mesh(params, path):
    """Mesh one part with gmsh (first-order tets) and write it as a .msh with physical groups."""
    try:
        import gmsh
    except ImportError:
        raise MeshError("hertz mesh: the gmsh Python package is needed to generate it (pip install gmsh)") from None
    # the geometry is built and meshed at R = 1, then scaled: OCC pads every bounding box by an absolute 1e-7,
    # which the face tests (TOL R) did not allow below R = 0.035 m ("no ymin surface found")
    R = 1.0
    scale = params["radius"]
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add(f"hertz_{params['part']}")
        groups = (_sphere if params["part"] == "sphere" else _block)(gmsh, R, params)
        missing = [name for name, tags in groups.items() if not tags]
        if missing:
            raise MeshError(f"hertz mesh: no {', '.join(missing)} surface found on the {params['part']} geometry")
        for name, tags in groups.items():
            gmsh.model.addPhysicalGroup(2, tags, name=name)
        gmsh.model.addPhysicalGroup(3, [t for _, t in gmsh.model.getEntities(3)], name=params["part"])
        _size_field(gmsh, R, params)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)     # Delaunay
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.model.mesh.generate(3)
        if scale != 1.0:
            gmsh.model.mesh.affineTransform([scale, 0, 0, 0, 0, scale, 0, 0, 0, 0, scale, 0])
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(path))
    except MeshError:
        raise
    except Exception as exc:  # noqa: BLE001 - gmsh reports every failure as a bare Exception
        raise MeshError(f"hertz mesh: gmsh failed on the {params['part']}: {exc}") from None
    finally:
        gmsh.finalize()
