"""Amaranth RTL of the springflat pipeline units.

Every width, constant and table comes from the golden model's objects
(:class:`golden_model.fixed.FormatSet`, :class:`golden_model.fixed.RsqrtConfig`); each unit is
bit-exact with its golden-model function. See ``docs/hardware-units.md``.
"""

from .area_error import AreaError
from .coarse_coefficients import CoarseCoefficients
from .coarse_node import CoarseNode
from .controller_units import BetaDivider, EnergyCheck, Normaliser
from .core import SpringflatCore
from .force_pass import ForcePass
from .guard_certificate import GuardCertificate
from .guard_commit import GuardCommit
from .guard_decision import GuardDecision
from .integrator import Integrator
from .level_scatter import LevelScatter
from .node_update import NodeUpdate
from .rsqrt import RsqrtUnit
from .stepgen import StepGenerator

__all__ = ["AreaError", "BetaDivider", "CoarseCoefficients", "CoarseNode", "EnergyCheck", "ForcePass", "GuardCertificate", "GuardCommit", "GuardDecision", "Integrator", "LevelScatter",
           "Normaliser", "NodeUpdate", "RsqrtUnit", "SpringflatCore", "StepGenerator"]
