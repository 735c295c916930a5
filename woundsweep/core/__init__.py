"""The bottom layer, pure Python: errors (`errors`), the shared contracts (`schema`: mesh tags,
stages, statuses, `StageResult`, units), format versions (`versions`), the run directory's
paths (`layout`), atomic and bounded file access (`fsutil`), provenance, the test-only fault
switch (`faults`) and the lazy re-exports of package ``__init__`` modules (`lazy`)."""
