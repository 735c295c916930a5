"""The solver's stress tensor at its sample points (`WoundForms.stress_tensor_samples`): the
von Mises of each sample tensor is the solver's own von Mises sample, and the cell means
(`forms.cell_means`) are what an export of the solver's tensors would hold."""

from __future__ import annotations

import numpy as np
import pytest
from skin_patch import box_patch

from woundsweep.config.solver import SolverSettings

pytestmark = pytest.mark.fem


def _vm(s: np.ndarray) -> np.ndarray:
    dev = s - np.trace(s, axis1=-2, axis2=-1)[..., None, None] / 3 * np.eye(3)
    return np.sqrt(1.5 * np.einsum("...ij,...ij->...", dev, dev))


def test_sample_tensors_give_the_solvers_von_mises() -> None:
    from woundsweep.physics.forms import cell_means
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel

    m = WoundModel(box_patch(), SolverSettings(element_degree=2))
    m.set_materials(JobMaterials.table2("normal", 30.0))
    u = m.forms.u
    X = u.function_space.tabulate_dof_coordinates()
    values = u.x.array.reshape(-1, 3)
    values[:, 0] = 0.04 * X[:, 0] + 0.02 * X[:, 1] ** 2  # a quadratic, non-uniform stretch
    values[:, 2] = -0.03 * X[:, 2] * X[:, 0]
    u.x.scatter_forward()
    t = m.forms.stress_tensor_samples()
    s = m.forms.von_mises_samples()
    assert s is not None and t.cauchy.shape == (*s.values.shape, 3, 3)
    np.testing.assert_allclose(_vm(t.cauchy), s.values, rtol=1e-9)
    assert np.allclose(t.cauchy, np.swapaxes(t.cauchy, -1, -2), rtol=1e-9, atol=1e-9)
    means = cell_means(t)
    J = np.linalg.det(t.F)
    np.testing.assert_allclose(means["det_F"], J @ t.weights, rtol=1e-12)
    # Von Mises is convex: that of a cell's mean tensor is at most the mean of its samples'.
    cell_vm = m.forms.von_mises_cells()
    assert np.all(_vm(means["cauchy_stress_kPa"]) <= cell_vm * (1 + 1e-6))
    # A cell inverted at every sample has no mean: NaN, which the export marks.
    bad = t._replace(F=np.where(np.arange(len(t.F))[:, None, None, None] == 0, -t.F, t.F))
    assert np.isnan(cell_means(bad)["cauchy_stress_kPa"][0]).all()


def test_a_p2_stage_stores_the_solvers_tensors_with_its_field(tmp_path) -> None:
    """A converged P2 stage keeps the solver's cell means in input cell order beside its
    von Mises field, and the solver file holds them: finite, symmetric, J > 0, and the von
    Mises of each cell's mean tensor at most its stored cell mean (von Mises is convex)."""
    import h5py

    from woundsweep.physics.job import run_stages, write_output
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel

    mesh = box_patch()
    m = WoundModel(mesh, SolverSettings(element_degree=2))
    recs = run_stages(m, JobMaterials.table2("stiff", 45.0), 2)
    assert all(r.cell_tensors is not None for r in recs)
    out = tmp_path / "job.h5"
    write_output(out, {"job_id": "x", "job_index": 0}, mesh, recs)
    with h5py.File(out, "r") as f:
        g = f["stage_2"]
        sigma, J, vm = g["cauchy_stress_kPa"][()], g["det_F"][()], g["von_mises_kPa"][()]
        E = g["green_lagrange_strain"][()]
    n = len(mesh.cells)
    assert sigma.shape == (n, 3, 3) and E.shape == (n, 3, 3) and J.shape == (n,)
    assert np.isfinite(sigma).all() and (J > 0).all()
    np.testing.assert_allclose(sigma, np.swapaxes(sigma, 1, 2), rtol=1e-5, atol=1e-4)
    assert np.all(_vm(sigma.astype(float)) <= vm * (1 + 1e-5) + 1e-6)
    # The healthy state at 45 degrees is homogeneous per layer: in input order, each layer's
    # cells hold one tensor, with the in-plane shear of the oblique dermis.
    tags = np.asarray(mesh.cell_tags)
    for tag in np.unique(tags):
        layer = sigma[tags == tag]
        assert np.ptp(layer, axis=0).max() < 1e-4 * np.abs(layer).max()
    assert np.abs(sigma[tags == tags.min()][:, 0, 1]).min() > 0.1
