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
