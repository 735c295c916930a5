"""woundsweep: a finite-element atlas of primary-intention wound closure.

Units throughout: lengths in mm, stresses and moduli in kPa, forces in mN.
"""

__version__ = "0.1.0"
__all__ = ["__version__"]
