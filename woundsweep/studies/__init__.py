"""Studies over many solves of one job: mesh convergence (`convergence`, ``woundsweep
converge``) and its order, GCI and least-squares fits (`gci`, pure)."""
