"""VTK export: the files read back with meshio (the library that wrote them) equal the result.

The .pvd collection is parsed with the standard library's XML parser, independently of
the writer.  The runs are a real 2D run of the thesis ball (padded with z = 0) and the
synthetic falling cube of test_figures3d (3D, closed form).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np
import pytest

import flexbody
from flexbody.cli import main
from flexbody.export import export_vtk
from flexbody.result import load_result
from tests.conftest import needs_cc
from tests.test_figures3d import falling_cube


def _collection(pvd: Path) -> list[tuple[float, str]]:
    """(timestep, file) of every DataSet of a .pvd, in file order."""
    root = ET.parse(pvd).getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]


def _check_frames(result, folder: Path, every: int = 1) -> None:
    """Every DataSet of run.pvd is the sample of the result at its time: positions, links, forces."""
    rows = _collection(folder / "run.pvd")
    nt, n, dim = result.positions.shape
    expected = list(range(0, nt, every)) + ([nt - 1] if (nt - 1) % every else [])
    assert [t for t, _ in rows] == [float(result.t[i]) for i in expected]  # exact: every time, in order
    assert len({f for _, f in rows}) == len(rows)
    for (_, name), i in zip(rows, expected, strict=True):
        mesh = meshio.read(folder / name)
        x = np.zeros((n, 3))
        x[:, :dim] = result.positions[i]
        np.testing.assert_array_equal(mesh.points, x)
        np.testing.assert_array_equal(mesh.cells_dict["line"], result.links)
        np.testing.assert_array_equal(mesh.cells_dict["vertex"].ravel(), np.arange(n))
        np.testing.assert_array_equal(mesh.point_data["contact_force"], result.contact_force[i])
        np.testing.assert_array_equal(mesh.point_data["phase"], result.contact_force[i] > 0)
        np.testing.assert_array_equal(mesh.point_data["velocity"][:, :dim], result.velocities[i])
        np.testing.assert_array_equal(mesh.point_data["velocity"][:, dim:], 0.0)
        np.testing.assert_array_equal(mesh.point_data["mass"], result.masses)


@pytest.fixture(scope="module")
def ball_run():
    """0.5 s of the thesis ball: it lands at about 0.28 s, so some frames have contact forces."""
    scene = flexbody.load_scene("thesis_ball")
    return scene, flexbody.simulate(scene, t_end=0.5, output_dt=0.01)


@needs_cc
def test_a_2d_run_reads_back_equal_padded_with_z_0(ball_run, tmp_path):
    scene, result = ball_run
    assert result.success and (result.contact_force > 0).any()
    pvd = export_vtk(result, tmp_path / "vtk", scene.grounds)
    assert pvd == tmp_path / "vtk" / "run.pvd"
    _check_frames(result, tmp_path / "vtk")
    ground = meshio.read(tmp_path / "vtk" / "grounds.vtu")
    (g,) = scene.grounds
    n = np.append(np.array(g.normal) / np.linalg.norm(g.normal), 0.0)
    np.testing.assert_allclose((ground.points - np.append(g.point, 0.0)) @ n, 0.0, atol=1e-12)  # in the plane


@pytest.mark.parametrize("every", [1, 7])
def test_a_3d_run_reads_back_equal_at_the_right_times(every, tmp_path):
    result, grounds = falling_cube(tilt=np.radians(30.0), point=(0.2, 0.1, -0.1), t_end=0.5, dt=0.01)
    export_vtk(result, tmp_path, grounds, every=every)
    _check_frames(result, tmp_path, every)
    assert len(list((tmp_path / "frames").iterdir())) == len(_collection(tmp_path / "run.pvd"))
    ground = meshio.read(tmp_path / "grounds.vtu")
    n = np.array(grounds[0].normal) / np.linalg.norm(grounds[0].normal)
    np.testing.assert_allclose((ground.points - grounds[0].point) @ n, 0.0, atol=1e-12)
    assert ground.cells_dict["quad"].shape == (1, 4)


def test_a_body_without_links_has_only_vertex_cells(tmp_path):
    result, _ = falling_cube(t_end=0.1)
    result.links = np.zeros((0, 2), int)
    export_vtk(result, tmp_path)
    mesh = meshio.read(tmp_path / "frames" / "frame_00000.vtu")
    assert set(mesh.cells_dict) == {"vertex"}
    np.testing.assert_array_equal(mesh.points, result.positions[0])


def test_every_must_be_a_whole_number_at_least_1(tmp_path):
    result, _ = falling_cube(t_end=0.1)
    for every in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="`every`"):
            export_vtk(result, tmp_path / "x", every=every)
    assert not (tmp_path / "x").exists()


# ---------------------------------------------------------------------------- the command line


@pytest.fixture
def run_dir(tmp_path):
    """A result folder as flexbody run writes it (a synthetic 3D run, no figures)."""
    result, _ = falling_cube(t_end=0.2, dt=0.01)
    return result, result.save(tmp_path / "run")


def test_export_command_writes_dir_vtk_and_replaces_it_whole(run_dir, capsys):
    result, folder = run_dir
    assert main(["export", str(folder), "--format", "vtk"]) == 0
    assert "run.pvd" in capsys.readouterr().out
    _check_frames(result, folder / "vtk")
    (folder / "vtk" / "stale.txt").write_text("from an earlier export")
    assert main(["export", str(folder), "--every", "5"]) == 0
    _check_frames(result, folder / "vtk", every=5)
    assert not (folder / "vtk" / "stale.txt").exists()
    assert sorted(p.name for p in folder.iterdir()) == ["result.npz", "summary.json", "vtk"]  # no temporary folder


def _one_line_error(capsys, code: int, *words: str) -> None:
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.startswith("error: ") and err.count("\n") == 1 and "Traceback" not in err
    for word in words:
        assert word in err


def test_export_of_a_missing_folder_exits_2_and_writes_nothing(tmp_path, capsys):
    code = main(["export", str(tmp_path / "nothing")])
    _one_line_error(capsys, code, "`DIR`", "nothing", "no such folder")
    assert os.listdir(tmp_path) == []


def test_export_of_a_folder_without_a_result_exits_2_and_writes_nothing(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("not a run")
    code = main(["export", str(tmp_path)])
    _one_line_error(capsys, code, "`DIR`", "result.npz", "summary.json")
    assert os.listdir(tmp_path) == ["notes.txt"]


def test_export_of_a_file_or_a_damaged_result_exits_2(run_dir, tmp_path, capsys):
    _, folder = run_dir
    _one_line_error(capsys, main(["export", str(folder / "summary.json")]), "not a folder")
    (folder / "result.npz").write_bytes(b"not a zip file")
    _one_line_error(capsys, main(["export", str(folder)]), "cannot be read")
    assert not (folder / "vtk").exists()


@pytest.mark.parametrize("every", ["0", "-2"])
def test_export_every_below_1_exits_2_and_writes_nothing(run_dir, capsys, every):
    _, folder = run_dir
    _one_line_error(capsys, main(["export", str(folder), "--every", every]), "`--every`", every)
    assert not (folder / "vtk").exists()


def test_export_refuses_a_file_named_vtk(run_dir, capsys):
    _, folder = run_dir
    (folder / "vtk").write_text("mine")
    _one_line_error(capsys, main(["export", str(folder)]), "is not a folder")
    assert (folder / "vtk").read_text() == "mine"


@needs_cc
def test_run_with_vtk_writes_the_export_into_the_run_folder(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", "thesis_ball", "--out", str(out), "--t-end", "0.35", "--output-dt", "0.01", "--no-figures",
                 "--vtk", "--quiet"]) == 0
    assert "vtk/run.pvd" in capsys.readouterr().out
    _check_frames(load_result(out), out / "vtk")
    assert (out / "vtk" / "grounds.vtu").is_file()
    assert sorted(p.name for p in out.iterdir()) == ["result.npz", "summary.json", "vtk"]
