"""The tools a pad can be: the compliant ball of ``models/pad_tool.sdf`` or a flat compliant disc.

``ToolConfig`` says which (``kind``), a disc's size and material, and how the constraint's orientation
rows are controlled with it (``orientation``)::

    tool: {kind: disc, radius: 0.025, thickness: 0.01, modulus: 3.0e5, resolution: 0.003}   # a task's config
    mount_tool(plant, arm, "tool0", tool=ToolConfig(kind="disc", radius=0.03))            # your station

Both tools hang from the same stem: the tool frame at the mounting flange, +z the approach axis a, and the
controlled point (frame ``pad_center``) 0.05 m along it: the ball's centre, or the centre of the disc's
face (the disc fills 0.05 - thickness <= z <= 0.05). The disc is a compliant-hydroelastic Drake
``Cylinder``: its pressure rises from 0 on its boundary to ``modulus`` at its mid-plane, half its thickness
deep, so a face pressed flat by delta carries p = modulus delta / (thickness / 2) (and less within half
a thickness of its rim, where the mesh's field falls to 0 on the side): a normal stiffness of about
2 modulus pi radius^2 / thickness and, about a diameter, 2 modulus pi radius^4 / (4 thickness).

A ball takes no moment about its centre, so the constraint's orientation rows are held by the controller
(``orientation: held``, kinematic rows). A disc must lie flat: with ``orientation: force`` (its default) the
rows are force-controlled (``core.constraints.with_force_rows``) with zero moment commanded, and the law
turns the disc until the pressure is centred under the controlled point, wherever the real surface is.
"""

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Optional

from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.schema import check_types

TOOL_KINDS = ("ball", "disc")
ORIENTATIONS = ("", "held", "force")
NORMAL_FORCES = ("", "model", "tool")
STEM_LENGTH = 0.05            # m along the tool's +z: the controlled point (the ball's centre, the disc's face)
BALL_RADIUS = 0.02            # m, models/pad_tool.sdf's pad


@dataclass
class ToolConfig:
    """The pad tool (module docstring): ``kind`` ball (``models/pad_tool.sdf``, 20 mm, its material from
    ``ContactConfig``) or disc (radius, thickness, modulus and resolution: read for a disc only).

    orientation: the constraint's orientation rows, "held" (kinematic rows, the controller holds the approach
        vector along the surface's normal) or "force" (force-controlled, zero moment: the tool lies flat on the
        real surface); "" is the tool's own: held for the ball, force for the disc.
    normal_force: which force the normal row holds at the command, "model" (along the model's normal) or
        "tool" (along the tool's axis: the real normal once the tool lies flat on a surface the model gets
        wrong; ``control.normal_force``); "" is the tool's own: tool for a disc with its orientation rows
        force-controlled, model otherwise.
    """

    kind: str = "ball"                 # ball (models/pad_tool.sdf) or disc (a flat compliant disc)
    radius: float = 0.025              # m, the disc's face radius
    thickness: float = 0.01            # m, the disc's thickness (at most the stem's 0.05 m)
    modulus: float = 3.0e5             # Pa, the disc's hydroelastic modulus (the ball's: contact.pad_modulus)
    resolution: float = 0.003          # m, the disc's mesh resolution hint (the ball's: contact.pad_resolution)
    orientation: str = ""              # the orientation rows: held | force ("": held for the ball, force for a disc)
    normal_force: str = ""             # the normal row's force: model | tool ("": tool for a disc with force rows)

    @property
    def is_disc(self) -> bool:
        return self.kind == "disc"

    @property
    def orientation_rows(self) -> str:
        """"held" or "force": how the constraint's orientation rows are controlled with this tool."""
        return self.orientation or ("force" if self.is_disc else "held")

    @property
    def normal_force_axis(self) -> str:
        """"model" or "tool": along which the normal row holds the commanded force with this tool."""
        return self.normal_force or ("tool" if self.is_disc and self.orientation_rows == "force" else "model")

    @property
    def offset(self) -> float:
        """m: the controlled point's distance from the surface it presses (the ball's radius, 0 for a disc's face)."""
        return 0.0 if self.is_disc else BALL_RADIUS

    def validate(self, prefix: str = "tool.") -> "ToolConfig":
        """ConfigError naming the field (types first, as for a file; a disc's fields given for the ball, which
        would not read them)."""
        check_types(self, ToolConfig, prefix.rstrip("."))
        if self.kind not in TOOL_KINDS:
            raise ConfigError(f"{prefix}kind must be one of {', '.join(TOOL_KINDS)}, got '{self.kind}'")
        if self.orientation not in ORIENTATIONS:
            raise ConfigError(f"{prefix}orientation must be held or force (or empty: the tool's own), got "
                              f"'{self.orientation}'")
        if self.normal_force not in NORMAL_FORCES:
            raise ConfigError(f"{prefix}normal_force must be model or tool (or empty: the tool's own), got "
                              f"'{self.normal_force}'")
        default = ToolConfig()
        if not self.is_disc:
            given = [name for name in ("radius", "thickness", "modulus", "resolution")
                     if getattr(self, name) != getattr(default, name)]
            if given:
                raise ConfigError(f"{prefix}{given[0]} is a disc's; the ball pad is models/pad_tool.sdf's (20 mm, its "
                                  "material contact.pad_modulus and contact.pad_resolution): set kind: disc")
            return self
        for name, unit, high in (("radius", "m", 0.5), ("thickness", "m", STEM_LENGTH), ("modulus", "Pa", math.inf),
                                 ("resolution", "m", math.inf)):
            number = float(getattr(self, name))
            if not (0 < number <= high and math.isfinite(number)):
                bound = f" and at most {high:g}" if math.isfinite(high) else ""
                raise ConfigError(f"{prefix}{name} must be a finite number > 0{bound} ({unit}), got {number}")
        return self


def disc_tool_sdf(tool: ToolConfig, name: str = "pad_tool", center_frame: str = "pad_center") -> str:
    """The SDF text of the disc tool of ``tool`` (a validated disc ToolConfig) as model ``name`` with its
    controlled point, the face's centre, as frame ``center_frame``."""
    radius, thickness = float(tool.radius), float(tool.thickness)
    z = STEM_LENGTH - thickness / 2
    mass = 0.2
    lateral = max(6e-5, mass * (3 * radius ** 2 + thickness ** 2) / 12)
    axial = max(3e-5, mass * radius ** 2 / 2)
    geometry = f"<cylinder><radius>{radius!r}</radius><length>{thickness!r}</length></cylinder>"
    return f"""<?xml version="1.0"?>
<sdf version="1.9">
  <model name="{name}">
    <link name="tool">
      <inertial>
        <pose>0 0 0.03 0 0 0</pose>
        <mass>{mass}</mass>
        <inertia><ixx>{lateral!r}</ixx><iyy>{lateral!r}</iyy><izz>{axial!r}</izz>
          <ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia>
      </inertial>
      <visual name="stem">
        <pose>0 0 0.015 0 0 0</pose>
        <geometry><cylinder><radius>0.012</radius><length>0.03</length></cylinder></geometry>
        <material><diffuse>0.6 0.6 0.65 1</diffuse></material>
      </visual>
      <visual name="pad_visual">
        <pose>0 0 {z!r} 0 0 0</pose>
        <geometry>{geometry}</geometry>
        <material><diffuse>0.95 0.85 0.2 1</diffuse></material>
      </visual>
      <collision name="pad">
        <pose>0 0 {z!r} 0 0 0</pose>
        <geometry>{geometry}</geometry>
        <drake:proximity_properties>
          <drake:compliant_hydroelastic/>
          <drake:hydroelastic_modulus>{float(tool.modulus)!r}</drake:hydroelastic_modulus>
          <drake:mesh_resolution_hint>{float(tool.resolution)!r}</drake:mesh_resolution_hint>
          <drake:hunt_crossley_dissipation>10</drake:hunt_crossley_dissipation>
          <drake:mu_dynamic>0.0</drake:mu_dynamic>
          <drake:mu_static>0.0</drake:mu_static>
        </drake:proximity_properties>
      </collision>
    </link>
    <frame name="{center_frame}" attached_to="tool"><pose relative_to="tool">0 0 {STEM_LENGTH} 0 0 0</pose></frame>
  </model>
</sdf>
"""


def tool_contact(tool: Optional[ToolConfig], contact: Any) -> Any:
    """``contact`` (a ContactConfig) with a disc's own modulus and mesh resolution as the pad's (the ball's
    come from ``contact``); ``contact`` itself for the ball or no tool."""
    if tool is None or not tool.is_disc:
        return contact
    return dataclasses.replace(contact, pad_modulus=float(tool.modulus), pad_resolution=float(tool.resolution))
