"""The physics: mechanisms as data (bodies, joints with their laws, a driver), the joint,
contact, friction and memory laws, the ideal mechanism, and the equations of motion of
any planar linkage with clearance joints. Imports nothing else of jaxcrank but
[`jaxcrank.errors`][].

Importing the package registers every joint law in
[`JOINT_LAWS`][jaxcrank.physics.joints.JOINT_LAWS], those defined outside
[`jaxcrank.physics.joints`][] included ([`Lubricated`][jaxcrank.physics.lubrication.Lubricated],
[`GuideClearance`][jaxcrank.physics.guide.GuideClearance], [`Worn`][jaxcrank.physics.wear.Worn]).
"""

from .guide import GuideClearance
from .lubrication import Lubricated
from .wear import Worn

__all__ = ["GuideClearance", "Lubricated", "Worn"]
