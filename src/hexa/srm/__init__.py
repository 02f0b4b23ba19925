"""Type II singularity release of the 3UPS+RPU (seed 003 sec 2.5, Algorithm 1): SRM-V1/V2, simulated robot,
Table 4 metrics and experiments."""
from __future__ import annotations

from hexa.srm.algorithm import M_INC, SingularityReleaseModule, SrmError, SrmStepInfo, implicated_limbs

__all__ = ["M_INC", "SingularityReleaseModule", "SrmError", "SrmStepInfo", "implicated_limbs"]
