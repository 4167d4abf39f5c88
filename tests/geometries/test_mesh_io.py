"""Tests of geometries/mesh_files/ and geometries/repair.py: mesh import, cleaning and orientation (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#8-built-in-geometries).

Every test names the invariant it checks. Meshes are built here with numpy; coordinates are
rounded to float32 so that every format (including binary STL, which stores float32) must
round-trip them exactly, and areas can be compared with ==.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from geometries.errors import InputError
from geometries.errors import MeshWarning
from geometries.mesh_files import read_surface, write_surface, write_vtp
from geometries.repair import (
    check_manifold,
    check_pair_distance,
    check_units,
    clean_surface,
    component_labels,
    drop_degenerate_triangles,
    merge_duplicate_vertices,
    orient_consistently,
    orient_pair,
    orient_towards,
    prepare_pair,
    prepare_surface,
    signed_volume_mm3,
)
from geometries.surface import TriangleSurface

FORMATS = ["stl", "obj", "ply", "vtk", "vtu", "vtp"]


# ------------------------------------------------------------------------------------------
# mesh builders
# ------------------------------------------------------------------------------------------


def f32(v: np.ndarray) -> np.ndarray:
    return np.asarray(v, dtype=np.float32).astype(np.float64)


def surf(v, t, name="test") -> TriangleSurface:
    return TriangleSurface(np.asarray(v, dtype=np.float64), np.asarray(t, dtype=np.int64), name)


def grid_patch(nx=6, ny=5, step=0.5, z=0.0, height=None) -> TriangleSurface:
    """Structured grid in a plane z = const (or z = height(x, y)), normals +z."""
    x, y = np.meshgrid(np.arange(nx + 1) * step, np.arange(ny + 1) * step, indexing="ij")
    zz = np.full_like(x, z) if height is None else height(x, y)
    v = np.stack([x.ravel(), y.ravel(), zz.ravel()], axis=1)
    idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    t = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return surf(f32(v), t, "grid")


def cube(side=2.0, origin=(0.0, 0.0, 0.0)) -> TriangleSurface:
    """Closed cube, outward normals."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                  [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=float) * side
    v += np.asarray(origin)
    t = [[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
         [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]]
    return surf(v, t, "cube")


def icosahedron(radius=10.0, center=(0.0, 0.0, 0.0), subdivisions=1) -> TriangleSurface:
    """Closed (subdivided) icosahedron with outward normals, float32-exact coordinates."""
    p = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0], [0, -1, p], [0, 1, p],
                  [0, -1, -p], [0, 1, -p], [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1]])
    t = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = v[uniq].mean(axis=1)
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = inv.ravel().reshape(3, -1) + len(v)  # midpoints of edges 01, 12, 20
        v = np.concatenate([v, mid])
        a, b, c = t.T
        t = np.concatenate([np.stack([a, m[0], m[2]], 1), np.stack([b, m[1], m[0]], 1),
                            np.stack([c, m[2], m[1]], 1), np.stack([m[0], m[1], m[2]], 1)])
    s = surf(f32(v * radius + np.asarray(center)), t, "ico")
    assert signed_volume_mm3(s) > 0
    return s


def cylinder_patch(radius=20.0, width=28.0, arc_deg=114.0, n_arc=24, n_w=8) -> TriangleSurface:
    """Talus-like cylinder patch (docs/method.md#8-built-in-geometries), axis along y, dome top at z = 0, normals outward."""
    th = np.radians(np.linspace(-arc_deg / 2, arc_deg / 2, n_arc + 1))
    y = np.linspace(-width / 2, width / 2, n_w + 1)
    T, Y = np.meshgrid(th, y, indexing="ij")
    v = np.stack([radius * np.sin(T), Y, radius * np.cos(T) - radius], -1).reshape(-1, 3)
    idx = np.arange(v.shape[0]).reshape(n_arc + 1, n_w + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    # (theta, y) increasing: d(theta) x d(y) points outward for this parametrisation
    t = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    s = surf(f32(v), t, "cylinder")
    top = np.argmax(s.centroids_mm[:, 2])
    assert s.unit_normals[top, 2] > 0.99
    return s


def moebius(n=20, radius=10.0, half_width=2.0) -> TriangleSurface:
    u = np.linspace(0, 2 * np.pi, n, endpoint=False)
    top, bot = [], []
    for ui in u:
        for w, lst in ((half_width, top), (-half_width, bot)):
            lst.append([(radius + w * np.cos(ui / 2)) * np.cos(ui),
                        (radius + w * np.cos(ui / 2)) * np.sin(ui), w * np.sin(ui / 2)])
    v = np.array(top + bot)
    t = []
    for i in range(n):
        a, b = i, i + n
        if i < n - 1:
            c, d = i + 1, i + 1 + n
        else:  # half twist: top meets bottom
            c, d = n, 0
        t += [[a, b, c], [b, d, c]]
    return surf(v, t, "moebius")


def total_area(s: TriangleSurface) -> float:
    return float(s.areas_mm2.sum())


def mesh_warnings(record) -> list[str]:
    return [str(w.message) for w in record if issubclass(w.category, MeshWarning)]


def read_clean(path, **kw) -> tuple[TriangleSurface, list[str]]:
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        s = prepare_surface(path, **kw)
    return s, mesh_warnings(rec)


# ------------------------------------------------------------------------------------------
# round trips
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("builder", [grid_patch, cube, icosahedron, cylinder_patch])
def test_round_trip_keeps_area_and_orientation_exactly(tmp_path, fmt, builder):
    """Invariant: write + read + clean returns the same triangles (area vectors bit-identical,
    so same total area and same orientation) in every format, with no repair warnings."""
    s = builder()
    path = tmp_path / f"mesh.{fmt}"
    write_surface(path, s)
    back, warns = read_clean(path)
    assert warns == []
    assert back.n_triangles == s.n_triangles
    assert total_area(back) == total_area(s)
    np.testing.assert_array_equal(back.area_vectors_mm2, s.area_vectors_mm2)
    assert back.source == str(path)


@pytest.mark.parametrize("binary", [True, False])
def test_stl_duplicates_merge_into_connected_manifold(tmp_path, binary):
    """Invariant: STL stores three private corners per triangle; after merging duplicates the
    icosahedron is one closed connected component with the original vertex count (V-E+F=2)."""
    s = icosahedron(subdivisions=2)
    path = tmp_path / "ico.stl"
    write_surface(path, s, binary=binary)
    raw = read_surface(path)
    # make the vertices private, as a naive STL reader would produce them
    private = surf(raw.vertices_mm[raw.triangles].reshape(-1, 3),
                   np.arange(3 * raw.n_triangles).reshape(-1, 3))
    merged = merge_duplicate_vertices(private)
    assert len(merged.vertices_mm) == len(s.vertices_mm)
    assert np.unique(component_labels(merged)).size == 1
    check_manifold(merged)
    n_e = len(np.unique(np.sort(np.concatenate(
        [merged.triangles[:, [0, 1]], merged.triangles[:, [1, 2]], merged.triangles[:, [2, 0]]]),
        axis=1), axis=0))
    assert len(merged.vertices_mm) - n_e + merged.n_triangles == 2


def test_near_duplicate_vertices_merge_within_tolerance():
    """Invariant: vertices closer than 1e-9 x bbox diagonal are one vertex; 1e-6 apart are not."""
    s = grid_patch()
    v = s.vertices_mm[s.triangles].reshape(-1, 3)
    rng = np.random.default_rng(1)
    diag = np.linalg.norm(np.ptp(s.vertices_mm, axis=0))
    jitter = v + rng.uniform(-1, 1, v.shape) * 1e-11 * diag
    private = surf(jitter, np.arange(len(v)).reshape(-1, 3))
    assert len(merge_duplicate_vertices(private).vertices_mm) == len(s.vertices_mm)
    far = surf(v + rng.uniform(-1, 1, v.shape) * 1e-6 * diag, private.triangles)
    assert len(merge_duplicate_vertices(far).vertices_mm) > len(s.vertices_mm)


def test_quads_are_split_into_two_triangles(tmp_path):
    """Invariant: a quad mesh reads as two triangles per quad with the same total area and
    normals (quad winding kept)."""
    import meshio

    x, y = np.meshgrid(np.arange(4.0), np.arange(3.0), indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    idx = np.arange(x.size).reshape(x.shape)
    q = np.stack([idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(),
                  idx[:-1, 1:].ravel()], 1)
    path = tmp_path / "quads.vtu"
    meshio.write_points_cells(path, v, [("quad", q)])
    s, warns = read_clean(path)
    assert warns == []
    assert s.n_triangles == 2 * len(q)
    assert total_area(s) == 6.0
    np.testing.assert_allclose(s.unit_normals, np.tile([0.0, 0.0, 1.0], (s.n_triangles, 1)))


def _legacy_polydata_text(s: TriangleSurface, version: str) -> str:
    pts = "\n".join(" ".join(repr(float(x)) for x in p) for p in s.vertices_mm)
    head = f"# vtk DataFile Version {version}\ntest\nASCII\nDATASET POLYDATA\n"
    head += f"POINTS {len(s.vertices_mm)} double\n{pts}\n"
    if version.startswith("5"):
        head += ("METADATA\nINFORMATION 1\nNAME L2_NORM_RANGE LOCATION vtkDataArray\n"
                 "DATA 2 9.5 10.5\n\n")
        off = " ".join(str(3 * i) for i in range(s.n_triangles + 1))
        conn = " ".join(str(i) for i in s.triangles.ravel())
        cells = (f"POLYGONS {s.n_triangles + 1} {3 * s.n_triangles}\nOFFSETS vtktypeint64\n"
                 f"{off}\nCONNECTIVITY vtktypeint64\n{conn}\n")
    else:
        rows = "\n".join("3 " + " ".join(map(str, t)) for t in s.triangles)
        cells = f"POLYGONS {s.n_triangles} {4 * s.n_triangles}\n{rows}\n"
    values = " ".join(["0.5"] * s.n_triangles)
    return (head + cells + f"CELL_DATA {s.n_triangles}\nSCALARS x float 1\nLOOKUP_TABLE default\n"
            f"{values}\n")


@pytest.mark.parametrize("version", ["4.2", "5.1"])
def test_legacy_vtk_polydata_is_read(tmp_path, version):
    """Invariant: legacy VTK POLYDATA (3D Slicer/ParaView surface export, unread by meshio 5)
    reads back the same triangles as written, classic and 5.1 OFFSETS/CONNECTIVITY layouts."""
    s = icosahedron()
    path = tmp_path / "poly.vtk"
    path.write_text(_legacy_polydata_text(s, version))
    back, warns = read_clean(path)
    assert warns == []
    np.testing.assert_array_equal(back.area_vectors_mm2, s.area_vectors_mm2)


def test_vtk_library_files_are_read(tmp_path):
    """Invariant: files written by VTK itself (legacy POLYDATA ascii/binary, VTP ascii, binary,
    appended raw, zlib-compressed; triangle strips) give the same closed surface and area."""
    vtk = pytest.importorskip("vtk")
    src = vtk.vtkSphereSource()
    src.SetThetaResolution(16)
    src.SetPhiResolution(12)
    src.SetRadius(10.0)
    src.Update()
    poly = src.GetOutput()
    strips = vtk.vtkStripper()
    strips.SetInputData(poly)
    strips.Update()
    ref = None
    cases = []
    for version in (42, 51):
        for binary in (False, True):
            w = vtk.vtkPolyDataWriter()
            w.SetFileVersion(version)
            w.SetFileType(2 if binary else 1)
            cases.append((w, f"legacy{version}_{int(binary)}.vtk", poly))
    for mode in ("ascii", "binary", "appended"):
        for compress in (False, True):
            w = vtk.vtkXMLPolyDataWriter()
            getattr(w, f"SetDataModeTo{mode.capitalize()}")()
            if mode == "appended":
                w.EncodeAppendedDataOff()
            if not compress:
                w.SetCompressorTypeToNone()
            cases.append((w, f"xml_{mode}_{int(compress)}.vtp", poly))
    w = vtk.vtkXMLPolyDataWriter()
    cases.append((w, "strips.vtp", strips.GetOutput()))
    w = vtk.vtkPolyDataWriter()
    cases.append((w, "strips.vtk", strips.GetOutput()))
    for writer, name, data in cases:
        writer.SetFileName(str(tmp_path / name))
        writer.SetInputData(data)
        writer.Write()
        s, warns = read_clean(tmp_path / name)
        assert warns == [], name
        assert np.unique(component_labels(s)).size == 1, name
        area = total_area(s)
        ref = area if ref is None else ref
        assert area == pytest.approx(ref, rel=1e-6), name
        assert signed_volume_mm3(s) > 0, name
        assert np.abs(s.area_vectors_mm2.sum(axis=0)).max() < 1e-9 * area, name


def test_other_vtk_dataset_types_and_higher_order_cells(tmp_path):
    """Invariant: VTK's readers take every legacy dataset type (a 2D image reads as 2 triangles
    per pixel, normals +z); higher-order triangles keep their corners (warning); a volume of
    voxels has no triangles (its 3D cells are not turned into a surface)."""
    vtk = pytest.importorskip("vtk")
    for dims, name in (((4, 3, 1), "sheet.vtk"), ((3, 3, 3), "volume.vtk")):
        image = vtk.vtkImageData()
        image.SetDimensions(*dims)
        writer = vtk.vtkStructuredPointsWriter()
        writer.SetFileName(str(tmp_path / name))
        writer.SetInputData(image)
        writer.Write()
    sheet, warns = read_clean(tmp_path / "sheet.vtk")
    assert warns == [] and sheet.n_triangles == 12 and total_area(sheet) == 6.0
    np.testing.assert_array_equal(sheet.unit_normals, np.tile([0.0, 0.0, 1.0], (12, 1)))
    with pytest.raises(InputError, match=r"no triangles \(cell types found: voxel\)"):
        read_surface(tmp_path / "volume.vtk")
    import meshio

    path = tmp_path / "tri6.vtu"
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.5, 0, 0], [0.5, 0.5, 0], [0, 0.5, 0]])
    meshio.write_points_cells(path, v, [("triangle6", np.array([[0, 1, 2, 3, 4, 5]]))])
    with pytest.warns(MeshWarning, match="corner nodes"):
        s = read_surface(path)
    np.testing.assert_array_equal(s.triangles, [[0, 1, 2]])


def test_damaged_vtk_files_are_refused(tmp_path):
    """Invariant: VTK readers report failures without raising; a legacy file whose data
    section ends early, a cut-off VTP and a VTP with out-of-range indices are InputErrors
    naming the file."""
    s = icosahedron()
    cut = tmp_path / "cut_data.vtk"
    cut.write_text(_legacy_polydata_text(s, "4.2").rsplit("\n", 2)[0] + "\n")  # no values
    with pytest.raises(InputError, match="could not read the mesh") as err:
        read_surface(cut, key="geometry.fixed")
    assert str(cut) in str(err.value) and "geometry.fixed" in str(err.value)
    whole = tmp_path / "whole.vtp"
    write_surface(whole, s)
    half = tmp_path / "half.vtp"
    half.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    with pytest.raises(InputError, match="could not read the mesh") as err:
        read_surface(half)
    assert str(half) in str(err.value)
    bad = tmp_path / "bad_index.vtp"
    t = s.triangles.copy()
    t[5] = [0, 1, len(s.vertices_mm) + 7]
    write_vtp(bad, s.vertices_mm, t)
    with pytest.raises(InputError, match="out of range"):
        read_surface(bad)


def _legacy_grid_text(offsets: list[int], connectivity: list[int], cell_types: list[int]) -> str:
    """A legacy (5.1) ASCII unstructured grid of 3 points with the given cell arrays, as written."""
    return ("# vtk DataFile Version 5.1\ndamaged\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 3 double\n0 0 0 1 0 0 0 1 0\n"
            f"CELLS {len(offsets)} {len(connectivity)}\nOFFSETS vtktypeint64\n{' '.join(map(str, offsets))}\n"
            f"CONNECTIVITY vtktypeint64\n{' '.join(map(str, connectivity))}\nCELL_TYPES {len(cell_types)}\n{' '.join(map(str, cell_types))}\n")


@pytest.mark.parametrize("offsets, connectivity, cell_types, detail", [
    ([0, 99999999999], [0, 1, 2], [5], "offsets do not walk"),  # VTK's own cell walk crashed the process
    ([0, 4, 3], [0, 1, 2], [5, 5], "offsets do not walk"),
    ([0, 3], [0, 1, 2], [199], "cell type 199 is not a VTK cell type"),
    ([0, 2], [0, 1], [5], "triangle cells with fewer than 3 points"),  # an IndexError before
])
def test_corrupted_vtk_cell_arrays_are_refused_before_vtk_walks_them(tmp_path, offsets, connectivity, cell_types, detail):
    """Invariant: VTK's legacy readers take a corrupted cell array as it comes (a mesh fuzz found
    them); its offsets, cell sizes and types are checked as numbers before any VTK call walks
    the cells, and refused naming the file. The same file with sound arrays reads."""
    pytest.importorskip("vtk")
    good = tmp_path / "good.vtk"
    good.write_text(_legacy_grid_text([0, 3], [0, 1, 2], [5]))
    assert read_surface(good).n_triangles == 1
    bad = tmp_path / "bad.vtk"
    bad.write_text(_legacy_grid_text(offsets, connectivity, cell_types))
    with pytest.raises(InputError, match=f"could not read the mesh .*{detail}") as err:
        read_surface(bad, key="geometry.mobile")
    assert str(bad) in str(err.value) and "geometry.mobile" in str(err.value)


def test_legacy_vtk_with_an_unparsable_version_line_is_refused(tmp_path):
    """Invariant: VTK reads a 5.1 file whose version it cannot parse with an older layout and
    crashed the process (a mesh fuzz found '5.l'); the first line is checked before VTK reads."""
    pytest.importorskip("vtk")
    bad = tmp_path / "version.vtk"
    bad.write_text(_legacy_grid_text([0, 3], [0, 1, 2], [5]).replace("Version 5.1", "Version 5.l"))
    with pytest.raises(InputError, match="its first line is .*5.l") as err:
        read_surface(bad)
    assert str(bad) in str(err.value)


@pytest.mark.parametrize("suffix", [".vtu", ".vtp"])
@pytest.mark.parametrize("attribute, value", [("NumberOfComponents", "-3"), ("NumberOfPoints", "99999999999999"), ("cells", "x")])
def test_vtk_xml_with_a_declared_size_out_of_range_is_refused(tmp_path, suffix, attribute, value):
    """Invariant: VTK's XML readers resize their arrays to the declared sizes unchecked, and
    NumberOfComponents="-3" (a mesh fuzz) aborted the process; such a size is refused naming
    the file and the attribute. The file as written reads."""
    pytest.importorskip("vtk")
    if attribute == "cells":
        attribute = "NumberOfCells" if suffix == ".vtu" else "NumberOfPolys"
    whole, surface = tmp_path / f"whole{suffix}", icosahedron()
    write_surface(whole, surface)
    assert read_surface(whole).n_triangles == surface.n_triangles
    text = whole.read_bytes()
    found = re.search(rf'{attribute}="[^"]*"'.encode(), text)
    assert found, attribute  # the writer declares it
    bad = tmp_path / f"bad{suffix}"
    bad.write_bytes(text[: found.start()] + f'{attribute}="{value}"'.encode() + text[found.end():])
    with pytest.raises(InputError, match=f"{attribute}=.*is not a whole number") as err:
        read_surface(bad)
    assert str(bad) in str(err.value)


def test_ply_with_its_header_cut_short_is_refused(tmp_path):
    """Invariant: a PLY file cut inside its header (a fuzz found it; meshio's reader looped for
    ever there) is refused naming the file; the whole file reads."""
    whole, surface = tmp_path / "whole.ply", icosahedron()
    write_surface(whole, surface)
    assert read_surface(whole).n_triangles == surface.n_triangles
    cut = tmp_path / "cut.ply"
    cut.write_bytes(whole.read_bytes()[: whole.read_bytes().index(b"end_header") - 5])
    with pytest.raises(InputError, match="no 'end_header' line") as err:
        read_surface(cut)
    assert str(cut) in str(err.value)


def _deflaters() -> list:
    """(compress, level) pairs the .vtp writer may use: zlib's, and ISA-L's where installed."""
    import zlib

    found = [pytest.param(zlib.compress, 1, id="zlib")]
    try:
        from isal.isal_zlib import compress
    except ImportError:
        return found
    return found + [pytest.param(compress, 2, id="isal")]


@pytest.mark.parametrize("compress, level", _deflaters())
def test_write_vtp_keeps_cell_data(tmp_path, monkeypatch, compress, level):
    """Invariant: write_vtp (also used for the result pressure maps) stores float64 points,
    int64 connectivity and the per-triangle arrays exactly, through either deflate (ISA-L's
    writes the same zlib streams VTK reads, faster)."""
    vtk = pytest.importorskip("vtk")
    from vtkmodules.util.numpy_support import vtk_to_numpy

    from geometries.mesh_files import vtk_family

    monkeypatch.setattr(vtk_family, "_compress", compress)
    monkeypatch.setattr(vtk_family, "_ZLIB_LEVEL", level)

    s = cylinder_patch()
    pressure = np.linspace(0.0, 1.0, s.n_triangles) ** 3
    contact = (pressure > 0.5).astype(np.int8)
    path = tmp_path / "p.vtp"
    write_vtp(path, s.vertices_mm, s.triangles, {"pressure_mpa": pressure, "in_contact": contact})
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    out = reader.GetOutput()
    np.testing.assert_array_equal(vtk_to_numpy(out.GetPoints().GetData()), s.vertices_mm)
    conn = vtk_to_numpy(out.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    np.testing.assert_array_equal(conn, s.triangles)
    cells = out.GetCellData()
    np.testing.assert_array_equal(vtk_to_numpy(cells.GetArray("pressure_mpa")), pressure)
    np.testing.assert_array_equal(vtk_to_numpy(cells.GetArray("in_contact")), contact)


def test_vtp_series_writes_each_file_as_it_would_be_written_alone(tmp_path):
    """Invariant: the files of a series (a run's time points), whose mesh and unchanged arrays
    are encoded once, are byte for byte the files written one by one; an array changed in place
    in the caller's buffer, or of another type with equal values, is encoded again."""
    from geometries.mesh_files.vtk_family import VtpSeries

    s = cylinder_patch()
    thickness = np.linspace(1.0, 2.0, s.n_triangles)  # the same at every time point
    buffer = np.zeros(s.n_triangles)
    series = VtpSeries()
    for k in range(4):
        buffer[:] = 0.0 if k >= 2 else np.arange(s.n_triangles) * k  # in place; time point 3 equals time point 2
        flags = (buffer > 3.0).astype(np.int8 if k < 3 else np.int32)  # time point 3: the values of 2, another type
        cells = {"pressure_mpa": buffer, "thickness_mm": thickness, "in_contact": flags}
        points = s.vertices_mm + [0.0, 0.1 * k, 0.0]
        write_vtp(tmp_path / f"series_{k}.vtp", points, s.triangles, cells, series=series)
        write_vtp(tmp_path / f"alone_{k}.vtp", points, s.triangles, {name: np.copy(v) for name, v in cells.items()})
        assert (tmp_path / f"series_{k}.vtp").read_bytes() == (tmp_path / f"alone_{k}.vtp").read_bytes(), k


def test_first_equal_rows_is_what_np_unique_gives_for_floats_and_integers():
    """Invariant: the duplicate finder of mesh cleaning (one sort of the rows' bits) maps every
    row to the first row equal to it exactly as np.unique(axis=0) does, -0.0 equal to 0.0."""
    from geometries.repair import _first_equal_rows

    rng = np.random.default_rng(7)
    for _ in range(50):
        n = int(rng.integers(1, 200))
        floats = rng.integers(-2, 3, size=(n, 3)) * 0.5
        floats[rng.random((n, 3)) < 0.3] = -0.0
        for rows in (floats, rng.integers(0, 4, size=(n, 3))):
            _, first, inverse = np.unique(rows, axis=0, return_index=True, return_inverse=True)
            np.testing.assert_array_equal(_first_equal_rows(rows), first[inverse.ravel()])


def test_write_vtp_point_arrays_keep_their_type_components_and_values_in_vtk(tmp_path):
    """Invariant: the .vtp writer (Python, no VTK) gives VTK's own reader every point array with
    its numeric type, its number of components and its values exactly (the FE maps write
    (n, 3) mobile points and int8 flags); a bool array reads as 0/1."""
    vtk = pytest.importorskip("vtk")
    from vtkmodules.util.numpy_support import vtk_to_numpy

    s = cylinder_patch()
    n = len(s.vertices_mm)
    arrays = {"mobile_point_mm": s.vertices_mm[::-1] * 1.5, "in_contact": (np.arange(n) % 3 == 0).astype(np.int8),
              "touched": np.arange(n) % 2 == 0, "count": np.arange(n, dtype=np.uint32)}
    path = tmp_path / "p.vtp"
    write_vtp(path, s.vertices_mm, s.triangles, point_data=arrays)
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    points = reader.GetOutput().GetPointData()
    for name, values in arrays.items():
        read = points.GetArray(name)
        assert read.GetNumberOfComponents() == (3 if values.ndim == 2 else 1), name
        expected = values.astype(np.uint8) if values.dtype == bool else values
        assert vtk_to_numpy(read).dtype == expected.dtype, name
        np.testing.assert_array_equal(vtk_to_numpy(read), expected)


# ------------------------------------------------------------------------------------------
# bad meshes, one class per test
# ------------------------------------------------------------------------------------------


def test_non_manifold_edge_is_refused(tmp_path):
    """Invariant: an edge shared by three triangles is an InputError naming the count, a
    location and the file."""
    v = [[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]]
    t = [[0, 1, 2], [1, 0, 3], [0, 1, 4]]
    path = tmp_path / "book.obj"
    write_surface(path, surf(v, t))
    with pytest.raises(InputError) as err:
        prepare_surface(path, key="geometry.fixed")
    msg = str(err.value)
    assert "1 non-manifold edges" in msg and "shared by 3 triangles" in msg
    assert "(0.5, 0, 0) mm" in msg
    assert str(path) in msg and "geometry.fixed" in msg and "expected" in msg


def test_moebius_strip_is_refused(tmp_path):
    """Invariant: a non-orientable surface is an InputError (no consistent spring side)."""
    path = tmp_path / "moebius.ply"
    write_surface(path, moebius())
    with pytest.raises(InputError, match="cannot be oriented consistently"):
        prepare_surface(path)


def test_flipped_triangles_are_repaired_and_counted(tmp_path):
    """Invariant: triangles wound against their neighbours are flipped back; the warning gives
    their number and the result equals the consistent input."""
    s = cylinder_patch()
    bad = np.array([3, 50, 51, 200, 301])
    t = s.triangles.copy()
    t[bad] = t[bad][:, [0, 2, 1]]
    path = tmp_path / "flipped.vtp"
    write_surface(path, surf(s.vertices_mm, t))
    back, warns = read_clean(path)
    assert len(warns) == 1 and re.search(r"\b5 triangles\b.*flipped", warns[0])
    np.testing.assert_array_equal(back.area_vectors_mm2, s.area_vectors_mm2)


def test_degenerate_and_duplicate_triangles_are_dropped_and_counted(tmp_path):
    """Invariant: repeated-index, zero-area and tiny triangles are dropped (counted), duplicate
    triangles too (counted); the rest of the surface is unchanged."""
    s = grid_patch()
    v = np.concatenate([s.vertices_mm, [[0.25, 0.0, 0.0]]])  # midpoint of edge (0, 0)-(0.5, 0)
    i0, i1 = 0, 6  # grid vertices at x = 0 and x = 0.5 on y = 0
    assert np.allclose(v[i1], [0.5, 0, 0])
    extra = np.array([[0, 0, 1], [i0, i1, len(v) - 1], [2, 3, 2]])
    dup = s.triangles[[4, 7]][:, [0, 2, 1]]  # same vertices, other winding
    t = np.concatenate([s.triangles, extra, dup])
    path = tmp_path / "degenerate.obj"
    write_surface(path, surf(v, t))
    back, warns = read_clean(path)
    assert any(re.search(r"\b3 degenerate triangles\b", w) for w in warns)
    assert any(re.search(r"\b2 duplicate triangles\b", w) for w in warns)
    assert back.n_triangles == s.n_triangles
    assert total_area(back) == total_area(s)
    assert len(back.vertices_mm) == len(s.vertices_mm)


def test_tiny_triangle_below_relative_area_is_dropped():
    """Invariant: area <= 1e-12 x mean area counts as degenerate even if not exactly zero."""
    s = grid_patch()
    v = np.concatenate([s.vertices_mm, [[0.25, 1e-14, 0.0]]])
    t = np.concatenate([s.triangles, [[0, 6, len(v) - 1]]])
    with pytest.warns(MeshWarning, match=r"\b1 degenerate"):
        out = drop_degenerate_triangles(surf(v, t))
    assert out.n_triangles == s.n_triangles


def test_metres_warning_and_unit_conversion(tmp_path):
    """Invariant: a mesh under 1 mm across warns 'looks like metres' and suggests units = "m";
    units = "m" multiplies lengths by 1000 and areas by exactly 1e6, without the warning."""
    s = cube(side=0.015625, origin=(0.5, 0.25, -0.125))  # a 15.6 mm cube written in metres
    path = tmp_path / "metres.stl"
    write_surface(path, s)
    mm, warns = read_clean(path)
    assert len(warns) == 1 and "metres" in warns[0] and 'units = "m"' in warns[0]
    m, warns_m = read_clean(path, units="m")
    assert warns_m == []
    assert total_area(m) == total_area(mm) * 1e6
    np.testing.assert_array_equal(m.areas_mm2, mm.areas_mm2 * 1e6)
    np.testing.assert_array_equal(m.vertices_mm, mm.vertices_mm * 1000.0)


def test_micrometres_warning():
    """Invariant: a mesh more than 2000 mm across warns about micrometres / wrong units."""
    with pytest.warns(MeshWarning, match="micrometres"):
        check_units(cube(side=30000.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_units(cube(side=30.0))  # a joint-sized mesh: silent


def test_unknown_units_are_refused(tmp_path):
    """Invariant: only "mm" and "m" are accepted units."""
    path = tmp_path / "c.stl"
    write_surface(path, cube())
    with pytest.raises(InputError, match="unknown length unit 'cm'") as err:
        read_surface(path, units="cm", key="geometry.units")
    assert '"mm" or "m"' in str(err.value)


def test_no_triangles_is_refused(tmp_path):
    """Invariant: a file with only line/volume cells is an InputError listing the cell types."""
    import meshio

    path = tmp_path / "lines.vtu"
    meshio.write_points_cells(path, np.eye(3), [("line", np.array([[0, 1], [1, 2]]))])
    with pytest.raises(InputError, match=r"no triangles \(cell types found: line\)"):
        read_surface(path)
    tet = tmp_path / "tet.vtu"
    meshio.write_points_cells(tet, np.vstack([np.eye(3), [[0, 0, 0]]]),
                              [("tetra", np.array([[0, 1, 2, 3]]))])
    with pytest.raises(InputError, match="tetra") as err:
        read_surface(tet)
    assert "surface" in str(err.value)


def test_nan_coordinates_are_refused(tmp_path):
    """Invariant: NaN or infinite coordinates are an InputError naming the file."""
    s = cube()
    v = s.vertices_mm.copy()
    v[3, 1] = np.nan
    path = tmp_path / "nan.obj"
    write_surface(path, surf(v, s.triangles))
    with pytest.raises(InputError, match="NaN or infinite") as err:
        read_surface(path, key="geometry.mobile")
    assert str(path) in str(err.value) and "geometry.mobile" in str(err.value)


def test_missing_file_is_refused(tmp_path):
    """Invariant: a missing file is an InputError naming the path and the scene key."""
    path = tmp_path / "nowhere" / "talus.stl"
    with pytest.raises(InputError, match="not found") as err:
        read_surface(path, key="geometry.mobile")
    assert str(path) in str(err.value) and "geometry.mobile" in str(err.value)


@pytest.mark.parametrize("suffix", [".stl", ".ply", ".vtk", ".vtu", ".vtp", ".obj"])
def test_garbage_file_is_refused(tmp_path, suffix):
    """Invariant: unreadable content never escapes as a meshio/numpy exception: InputError."""
    path = tmp_path / f"garbage{suffix}"
    path.write_bytes(np.random.default_rng(3).bytes(1000) + b"\nsolid junk 1 2\n")
    with pytest.raises(InputError) as err:
        read_surface(path, key="geometry.fixed")
    assert str(path) in str(err.value)


def test_unknown_format_is_refused(tmp_path):
    """Invariant: an unknown extension is an InputError listing the supported formats."""
    path = tmp_path / "talus.xyz"
    path.write_text("1 2 3\n")
    with pytest.raises(InputError, match=r"unknown mesh format '\.xyz'.*STL"):
        read_surface(path)


def test_bodies_too_far_apart(tmp_path):
    """Invariant: bodies further apart than 10 h_max + longest edge are an InputError giving the
    distance; close bodies return the smallest vertex distance."""
    mobile = cylinder_patch()
    fixed = grid_patch(nx=8, ny=8, step=5.0, z=100.0)
    with pytest.raises(InputError, match="bodies too far apart: no spring can be a candidate"):
        check_pair_distance(mobile, fixed, 3.5)
    near = grid_patch(nx=8, ny=8, step=5.0, z=1.5)
    near = surf(near.vertices_mm - [20.0, 20.0, 0.0], near.triangles)
    assert check_pair_distance(mobile, near, 3.5) == pytest.approx(1.5, abs=1e-6)


# ------------------------------------------------------------------------------------------
# orientation
# ------------------------------------------------------------------------------------------


def test_closed_mesh_is_turned_outward():
    """Invariant: a closed mesh given inward with some triangles flipped comes out with positive
    signed volume, area vectors summing to zero, and the count of inconsistent triangles."""
    s = icosahedron(subdivisions=2, center=(50.0, -30.0, 7.0))
    t = s.triangles[:, [0, 2, 1]].copy()  # all inward
    t[[1, 17, 100]] = t[[1, 17, 100]][:, [0, 2, 1]]  # three of them outward
    with pytest.warns(MeshWarning, match=r"\b3 triangles"):
        out = orient_consistently(surf(s.vertices_mm, t))
    assert signed_volume_mm3(out) > 0
    np.testing.assert_allclose(signed_volume_mm3(out), signed_volume_mm3(s), rtol=1e-12)
    assert np.abs(out.area_vectors_mm2.sum(axis=0)).max() < 1e-12 * total_area(out)
    np.testing.assert_array_equal(out.area_vectors_mm2, s.area_vectors_mm2)


def test_components_are_oriented_independently():
    """Invariant: two separate closed bodies in one file are each turned outward."""
    a, b = cube(), icosahedron(center=(40.0, 0.0, 0.0))
    v = np.concatenate([a.vertices_mm, b.vertices_mm])
    t = np.concatenate([a.triangles, b.triangles[:, [0, 2, 1]] + len(a.vertices_mm)])
    out = clean_surface(surf(v, t))
    labels = component_labels(out)
    assert np.unique(labels).size == 2
    for c in np.unique(labels):
        part = surf(out.vertices_mm, out.triangles[labels == c])
        assert signed_volume_mm3(part) > 0


def test_orient_pair_cylinder_patch_and_plane():
    """Invariant (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs): M's normals point towards F (positive z at the dome top) and F's
    normals towards M (down), whatever the input sign of both open patches."""
    mobile = cylinder_patch()
    mobile_wrong = surf(mobile.vertices_mm, mobile.triangles[:, [0, 2, 1]])  # into the bone
    plane = grid_patch(nx=10, ny=8, step=4.0, z=1.5)
    plane = surf(plane.vertices_mm - [20.0, 16.0, 0.0], plane.triangles)  # normals +z: wrong
    m, f = orient_pair(mobile_wrong, plane)
    top = np.argmax(m.centroids_mm[:, 2])
    assert m.unit_normals[top, 2] > 0.99
    assert np.all(f.unit_normals[:, 2] < -0.99)
    # already right: nothing changes
    m2, f2 = orient_pair(m, f)
    np.testing.assert_array_equal(m2.triangles, m.triangles)
    np.testing.assert_array_equal(f2.triangles, f.triangles)


@pytest.mark.parametrize("near_mm", [None, 3.5])
@pytest.mark.parametrize("arc_deg", [180.0, 240.0, 330.0])
def test_surface_wrapping_round_a_condyle_is_oriented_by_the_triangles_near_the_other_body(arc_deg, near_mm):
    """Invariant (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs): an open surface wrapping round a condyle (a cylinder arc up to
    330 deg) over a small plateau 0.5 mm away faces the plateau where they meet, whatever
    sign it is given. The far triangles of the wrap see the plateau behind them; with every
    triangle voting they outvoted the near ones and turned the surface inside out."""
    radius = 20.0
    theta = np.radians(np.linspace(-arc_deg / 2, arc_deg / 2, 61))
    x = np.linspace(-10.0, 10.0, 11)
    xx, tt = np.meshgrid(x, theta, indexing="ij")
    v = np.column_stack([xx.ravel(), radius * np.sin(tt.ravel()), radius * np.cos(tt.ravel()) - radius])
    idx = np.arange(xx.size).reshape(xx.shape)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    wrap = surf(v, np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])]))
    plateau = grid_patch(nx=8, ny=8, step=1.0, z=0.5)
    plateau = surf(plateau.vertices_mm - [4.0, 4.0, 0.0], plateau.triangles)
    outward = wrap.centroids_mm - np.column_stack([wrap.centroids_mm[:, 0], np.zeros(wrap.n_triangles), np.full(wrap.n_triangles, -radius)])
    for given in (wrap, surf(wrap.vertices_mm, wrap.triangles[:, ::-1])):
        for fixed_is_wrap in (True, False):
            pair = (plateau, given) if fixed_is_wrap else (given, plateau)
            m, f = orient_pair(*pair, near_mm=near_mm)
            w, p = (f, m) if fixed_is_wrap else (m, f)
            # every triangle of the wrap outward (away from its axis), the plateau facing down
            assert np.all(np.einsum("ij,ij->i", w.unit_normals, outward) > 0)
            assert np.all(p.unit_normals[:, 2] < -0.99)


def test_orient_towards_closed_shell_enclosing_other_body_points_inward():
    """Invariant: a closed fixed shell around the mobile body gets inward normals (towards M);
    the enclosed closed mobile body stays outward."""
    inner = icosahedron(radius=1.0, subdivisions=2)
    outer = icosahedron(radius=1.5, subdivisions=2)
    m, f = orient_pair(inner, outer)
    assert signed_volume_mm3(m) > 0
    assert signed_volume_mm3(f) < 0
    # seen from outside, a closed fixed body keeps outward normals
    far = orient_towards(outer, inner.vertices_mm + [10.0, 0.0, 0.0])
    assert signed_volume_mm3(far) > 0


def test_prepare_pair_from_files(tmp_path):
    """Invariant: the scene entry point reads both files, orients M towards F and F towards M,
    and refuses bodies too far apart for h_max."""
    mobile = cylinder_patch()
    plane = grid_patch(nx=10, ny=8, step=4.0, z=1.5)
    plane = surf(plane.vertices_mm - [20.0, 16.0, 0.0], plane.triangles)
    write_surface(tmp_path / "talus.stl", surf(mobile.vertices_mm, mobile.triangles[:, [0, 2, 1]]))
    write_surface(tmp_path / "tibia.ply", plane)
    m, f = prepare_pair(tmp_path / "talus.stl", tmp_path / "tibia.ply", max_spring_length_mm=3.5)
    assert m.unit_normals[np.argmax(m.centroids_mm[:, 2]), 2] > 0.99
    assert np.all(f.unit_normals[:, 2] < -0.99)
    assert total_area(m) == total_area(mobile)
    far = surf(plane.vertices_mm + [0.0, 0.0, 200.0], plane.triangles)
    write_surface(tmp_path / "far.vtp", far)
    with pytest.raises(InputError, match="too far apart"):
        prepare_pair(tmp_path / "talus.stl", tmp_path / "far.vtp", max_spring_length_mm=3.5)


def test_all_degenerate_mesh_is_refused(tmp_path):
    """Invariant: a mesh whose triangles all have zero area is an InputError, not an empty
    surface."""
    v = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]
    path = tmp_path / "flat.obj"
    write_surface(path, surf(v, [[0, 1, 2], [1, 2, 3]]))
    with pytest.raises(InputError, match="degenerate"):
        read_clean(path)


def test_mixed_polygons_in_legacy_vtk_are_triangulated(tmp_path):
    """Invariant: a classic legacy POLYGONS list with mixed sizes (hexagon + quad + triangle)
    becomes a fan/split triangulation with the same area and the polygons' winding (+z)."""
    ang = np.radians(np.arange(6) * 60.0)
    hexagon = np.stack([np.cos(ang), np.sin(ang), np.zeros(6)], axis=1)  # counter-clockwise
    quad = np.array([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0], [0.5, np.sin(ang[1]), 0]])
    v = np.concatenate([hexagon, quad[1:3], [[1.0, -1.0, 0.0]]])
    polys = [[0, 1, 2, 3, 4, 5], [0, 6, 7, 1], [0, 8, 6]]
    lines = "\n".join(f"{len(p)} " + " ".join(map(str, p)) for p in polys)
    pts = "\n".join(" ".join(repr(float(x)) for x in p) for p in v)
    path = tmp_path / "mixed.vtk"
    path.write_text(f"# vtk DataFile Version 3.0\nmixed\nASCII\nDATASET POLYDATA\n"
                    f"POINTS {len(v)} double\n{pts}\n"
                    f"POLYGONS {len(polys)} {sum(len(p) + 1 for p in polys)}\n{lines}\n")
    s, warns = read_clean(path)
    assert warns == []
    assert s.n_triangles == 4 + 2 + 1
    expected = 1.5 * 3 ** 0.5 + 0.5 * (1.5 + np.sin(ang[1])) + 0.5  # shoelace areas
    assert total_area(s) == pytest.approx(expected, rel=1e-14)
    assert np.all(s.unit_normals[:, 2] > 0.999)


def test_write_to_unknown_format_is_refused(tmp_path):
    """Invariant: writing to an extension no writer knows is an InputError, not a KeyError."""
    with pytest.raises(InputError, match="unknown mesh format"):
        write_surface(tmp_path / "a.xyz", cube())
