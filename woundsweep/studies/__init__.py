"""Studies over many solves of one job: mesh convergence (`convergence`, ``woundsweep
converge``), its order, GCI and least-squares fits (`gci`, pure) and its figure (`figure`)."""
