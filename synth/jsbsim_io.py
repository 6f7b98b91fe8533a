"""The one interface between JSBSim and the rest of the testbed.

JSBSim works in English units (ft, in, lbf, slug, Rankine, psf) and places masses and points in its
*structural* frame (x aft, y right, z up, inches, arbitrary origin). The testbed works in SI and in
body axes (x forward, y right, z down, metres, origin at the airframe's reference point, SPEC §2).
Every unit and frame conversion between the two lives in this module and nowhere else.

It also

* generates, at run time, a patched copy of a JSBSim aircraft in a cache directory (never committed):
  for the ``f16`` the yaw-damper PID's ``<output>fcs/rudder-pos-norm</output>`` is removed, because it
  overwrites the rudder position and limits rudder to about 5 deg and sideslip to about 1 deg
  (SPEC §7); every model gets a zero-weight ``Ballast`` point mass whose weight and position are set
  per aircraft at run time;
* corrects the ``f16``'s flaperon mixing. The shipped FCS sums the two flaperons, ``(-tef - ail) +
  (tef - ail) = -2 ail``, times 1.4324, into ``fcs/flaperon-mix-rad``, the deflection that the
  trailing-edge-flap lift and drag (``aero/coefficient/CLDflaps``, 0.35 per rad times the
  ground-effect factor; ``CDDflaps``, 0.08 per rad) take: the flap lift followed the roll command
  (an aileron step of +-0.25 moved the flaps' lift coefficient by -+0.20 within 0.5 s at Mach 0.4,
  6000 m) and the flaps gave none. The sum should have been the difference
  of the two mirrored surfaces (each flaperon's trailing-edge-down deflection is ``tef +- ail``: the
  mean, the symmetric flap, is ``tef``; the half difference, the aileron, already drives the roll
  and yaw terms through ``fcs/aileron-pos-rad``), and 1.4324 = 2.864789 / 2 is norm per rad where
  rad per norm was meant (a sign flip alone gives 2.86 rad of "flap", +1.0 of lift coefficient). The
  patch makes ``fcs/flaperon-mix-rad`` the symmetric flap deflection, rad: ``fcs/tef-control`` (the
  scheduled flap, norm, rate-limited to full travel in 3 s) times 1 / 2.864789 rad per norm, so the
  full flap (``fcs/tef-pos-rad`` = 0.349 rad, 20 deg) adds 0.35 * 0.349 = 0.122 to the lift
  coefficient and 0.08 * 0.349 = 0.028 to the drag coefficient out of ground effect, and the aileron
  none. The flaps come down only with the landing-gear handle (``gear/gear-cmd-norm`` >= 0.5) and,
  as the shipped schedule says, below 250 kt calibrated; above Mach 0.9 they reflex to -0.0349 rad
  as shipped. A flaperon reaching its stop when flap and aileron add is not modelled (the shipped
  roll terms ignore it too); ``fcs/left-`` and ``right-flaperon-norm`` are left as shipped (no aero
  term reads them);
* lets the ``f16``'s pilot command reach the alpha limit of the real F-16. The shipped pitch channel
  clips stick plus trim (``fcs/elevator-cmd-limiter``) to -1 nose up; its loop is proportional only
  (the integrator of ``fcs/g-load-pid`` is held by its ``trigger``, 1 in flight) with an alpha
  feedback of 1.047 per rad, so full aft stick balances at 17-20 deg of alpha wings level at low
  dynamic pressure and at 12-14 deg in a Mach 0.4-0.6 wind-up turn, short of the real F-16's
  25 deg limiter and of the 28-30 deg the FCS's own comments aim at; a calibration campaign needs
  the nose probe and the tables' upper breakpoints above 20 deg. The patch moves that
  clip to :data:`F16_AFT_COMMAND_STOP_NORM` (-2.5): full aft command then balances at 22-24 deg in
  a 1.5 g turn at Mach 0.3-0.4 and low dynamic pressure (20.9 deg for the most forward CG at Mach
  0.3, 3000 m), still below 25 deg; the elevator's own stop (``fcs/pitch-scheduler`` clipped to
  -1, 25 deg of surface) and every other gain are as shipped, so a command within the shipped
  range -1..0.44 flies exactly as before;
* writes a flat, non-rotating planet definition (a sphere so large that curvature and transport
  rate are negligible, with constant gravity) and builds an :class:`jsbsim.FGFDMExec` on it or on
  JSBSim's default rotating WGS84 earth;
* reads all :class:`synth.truth.TruthTrajectory` signals from a running FDM into a preallocated
  buffer, one row per step, and converts the buffer to SI in one vectorized pass.
"""

from __future__ import annotations

import hashlib
import math
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import jsbsim
import numpy as np

from synth.truth import TruthTrajectory

JSBSIM_VERSION: str = jsbsim.__version__

# --- unit conversions (exact definitions; the only place the testbed knows English units) -------
FT_TO_M = 0.3048
IN_TO_M = 0.0254
LBF_TO_N = 4.4482216152605
LBM_TO_KG = 0.45359237
SLUG_TO_KG = LBF_TO_N / FT_TO_M  # 1 slug = 1 lbf s^2 / ft
PSF_TO_PA = LBF_TO_N / FT_TO_M**2
RANKINE_TO_K = 5.0 / 9.0
SLUGFT3_TO_KGM3 = SLUG_TO_KG / FT_TO_M**3
DEG_TO_RAD = math.pi / 180.0

#: The f16's full trailing-edge-flap deflection, rad (20 deg; its ``fcs/tef-pos-rad`` switch).
F16_TEF_DOWN_RAD = 0.349
#: The f16's ``fcs/tef-pos-norm`` gain is 2.864789 norm per rad; the flaperon mix takes it back.
F16_TEF_RAD_PER_NORM = 1.0 / 2.864789
#: The condition the patch adds to the f16's flaps-down test: the landing-gear handle is down.
F16_GEAR_HANDLE_DOWN_TEST = "gear/gear-cmd-norm ge 0.5"
#: Nose-up stop of the f16's pilot command (stick plus trim), norm: -1 as shipped, extended so
#: that full aft command reaches about the real F-16's alpha limit (module docstring).
F16_AFT_COMMAND_STOP_NORM = -2.5

#: Name of the point mass added to every patched model.
BALLAST_NAME = "Ballast"

#: Radius of the "flat" planet, m. Large enough that over a 100 s run at Mach 0.9 (~30 km) the
#: local vertical turns by 1e-6 rad and gravity changes by 1e-5 relative over 15 km of altitude,
#: small enough that double-precision ECEF positions still resolve micrometres.
FLAT_PLANET_RADIUS_M = 3.0e9
#: Standard gravity used on the flat planet, m/s^2.
FLAT_PLANET_G_MPS2 = 9.80665

#: JSBSim integrator codes (FGPropagate::eIntegrateType): 3 = Adams-Bashforth 2, 5 = Adams-Bashforth 4.
#: SPEC §7 suggests 3/5/3/5; measured on a 30 s doublet/roll/rudder run, AB4 for the attitude
#: quaternion (position/rotational 5) cuts the flat-earth RK4 mismatch from 0.017 m/s, 0.016 deg
#: to 0.006 m/s, 0.012 deg, so it is used here.
_INTEGRATORS_FLAT = {
    "simulation/integrator/rate/rotational": 3,
    "simulation/integrator/rate/translational": 5,
    "simulation/integrator/position/rotational": 5,
    "simulation/integrator/position/translational": 5,
}


def cache_root() -> Path:
    """Directory holding generated JSBSim files (``$FPR_CACHE_DIR`` or ``~/.cache/fpr``)."""
    env = os.environ.get("FPR_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "fpr"


def _flat_planet_xml() -> str:
    radius_ft = FLAT_PLANET_RADIUS_M / FT_TO_M
    gm_ft3ps2 = (FLAT_PLANET_G_MPS2 / FT_TO_M) * radius_ft**2
    return (
        '<?xml version="1.0"?>\n'
        '<planet name="flat-nonrotating">\n'
        "  <!-- generated by synth/jsbsim_io.py: a huge sphere, no rotation, no J2 -->\n"
        f'  <semimajor_axis unit="FT"> {radius_ft!r} </semimajor_axis>\n'
        f'  <semiminor_axis unit="FT"> {radius_ft!r} </semiminor_axis>\n'
        '  <rotation_rate unit="RAD/SEC"> 0.0 </rotation_rate>\n'
        f"  <GM> {gm_ft3ps2!r} </GM>\n"
        "  <J2> 0.0 </J2>\n"
        "</planet>\n"
    )


def _f16_component(root: ET.Element, tag: str, name: str, what: str) -> ET.Element:
    """The f16 FCS component ``<tag name=name>``, or an error saying which patch no longer fits."""
    comp = root.find(f".//flight_control//{tag}[@name='{name}']")
    if comp is None:
        raise RuntimeError(
            f"JSBSim {JSBSIM_VERSION}: f16 has no <{tag} name='{name}'>; the {what} patch no longer "
            "applies - check the model's FCS and update synth/jsbsim_io.py (_patch_model_xml)"
        )
    return comp


def _patch_f16_flaperons(root: ET.Element) -> None:
    """Symmetric trailing-edge flap from the flap schedule, not from the roll command (module doc)."""
    what = "flaperon-mixing"
    tef = _f16_component(root, "switch", "fcs/tef-pos-rad", what)
    down = [t for t in tef.findall("test") if float(t.get("value", "nan")) == F16_TEF_DOWN_RAD]
    if len(down) != 1 or "vc-kts" not in (down[0].text or ""):
        raise RuntimeError(
            f"JSBSim {JSBSIM_VERSION}: the f16's fcs/tef-pos-rad has no single 'flaps down "
            f"{F16_TEF_DOWN_RAD} rad below a calibrated airspeed' test; the {what} patch no longer "
            "applies - check the model's FCS and update synth/jsbsim_io.py (_patch_model_xml)"
        )
    # the F-16's flaps come down with the landing-gear handle, not with airspeed alone
    down[0].text = (down[0].text or "").rstrip() + f"\n     {F16_GEAR_HANDLE_DOWN_TEST}\n    "
    mix = _f16_component(root, "pure_gain", "fcs/flaperon-mix-rad", what)
    for child in list(mix):
        mix.remove(child)
    ET.SubElement(mix, "input").text = "fcs/tef-control"
    ET.SubElement(mix, "gain").text = repr(F16_TEF_RAD_PER_NORM)


def _patch_f16_pitch_authority(root: ET.Element) -> None:
    """Nose-up stop of stick plus trim at :data:`F16_AFT_COMMAND_STOP_NORM` (module doc)."""
    what = "pitch-authority"
    lim = _f16_component(root, "summer", "fcs/elevator-cmd-limiter", what)
    stop = lim.find("clipto/min")
    if stop is None or float(stop.text or "nan") != -1.0:
        raise RuntimeError(
            f"JSBSim {JSBSIM_VERSION}: the f16's fcs/elevator-cmd-limiter no longer clips at -1; "
            f"the {what} patch no longer applies - check the model's FCS and update "
            "synth/jsbsim_io.py (_patch_model_xml)"
        )
    stop.text = repr(F16_AFT_COMMAND_STOP_NORM)


def _patch_model_xml(model: str, text: bytes) -> bytes:
    """Return the patched aircraft definition (f16: rudder, flaperon and pitch-authority fixes;
    ballast point mass)."""
    root = ET.fromstring(text)
    if model == "f16":
        pid = _f16_component(root, "pid", "fcs/yaw-load-pid", "rudder (SPEC §7)")
        if pid.find("output") is None:
            raise RuntimeError(
                f"JSBSim {JSBSIM_VERSION}: f16 has no fcs/yaw-load-pid with an <output>; the rudder "
                "fix of SPEC §7 no longer applies - check the model and update synth/jsbsim_io.py"
            )
        for out in pid.findall("output"):
            pid.remove(out)
        _patch_f16_flaperons(root)
        _patch_f16_pitch_authority(root)
    mass_balance = root.find("mass_balance")
    if mass_balance is None:
        raise RuntimeError(f"JSBSim model {model!r} has no <mass_balance>; cannot add ballast")
    pm = ET.SubElement(mass_balance, "pointmass", {"name": BALLAST_NAME})
    ET.SubElement(pm, "weight", {"unit": "LBS"}).text = "0.0"
    loc = ET.SubElement(pm, "location", {"unit": "IN"})
    for axis in "xyz":
        ET.SubElement(loc, axis).text = "0.0"
    return b'<?xml version="1.0"?>\n' + ET.tostring(root, encoding="utf-8")


def patched_root_dir(model: str) -> Path:
    """Build (once, atomically) and return a JSBSim root directory holding the patched ``model``.

    The directory is ``<cache_root>/jsbsim-<version>-<model>-<hash>`` where the hash covers the
    patched model file and the planet definition, so a JSBSim upgrade or any patch change gives a
    fresh directory (directories built by older code are left in place, never read). Parallel
    processes may race to build it: each builds in its own temporary directory and renames it into
    place; the loser discards its copy.

    Parameters
    ----------
    model : JSBSim aircraft directory name, e.g. ``"f16"``.

    Returns
    -------
    Path to pass to ``jsbsim.FGFDMExec(root_dir=...)``.
    """
    src_root = Path(jsbsim.get_default_root_dir())
    src_file = src_root / "aircraft" / model / f"{model}.xml"
    if not src_file.exists():
        raise FileNotFoundError(
            f"JSBSim {JSBSIM_VERSION} ships no aircraft {model!r} ({src_file} missing); "
            "check jsbsim_model in the airframe TOML"
        )
    patched = _patch_model_xml(model, src_file.read_bytes())
    planet = _flat_planet_xml().encode()
    # keyed by the generated bytes themselves: any change of a patch (or of the shipped model) gives
    # a new directory, so a cache built by older code is never served
    digest = hashlib.sha256(patched + planet + model.encode()).hexdigest()
    final = cache_root() / f"jsbsim-{JSBSIM_VERSION}-{model}-{digest[:12]}"
    if (final / "aircraft" / model / f"{model}.xml").exists():
        return final
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".build-", dir=final.parent))
    try:
        tmp.chmod(0o755)  # mkdtemp makes it private; the cache may be shared
        ac_dir = tmp / "aircraft" / model
        ac_dir.mkdir(parents=True)
        for item in (src_root / "aircraft" / model).iterdir():
            if item.name != f"{model}.xml":
                os.symlink(item, ac_dir / item.name)
        (ac_dir / f"{model}.xml").write_bytes(patched)
        for shared in ("engine", "systems"):
            os.symlink(src_root / shared, tmp / shared)
        (tmp / "flat_planet.xml").write_bytes(planet)
        try:
            os.rename(tmp, final)
        except OSError:
            # another process won the race; its copy is identical
            if not (final / "aircraft" / model / f"{model}.xml").exists():
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return final


@dataclass(frozen=True)
class StructuralFrame:
    """Maps JSBSim structural coordinates (x aft, y right, z up, in) to body axes (m).

    Attributes
    ----------
    origin_in : (3,) structural coordinates of the body-axis origin (the reference point), in.
    """

    origin_in: tuple[float, float, float]

    def to_body_m(self, xyz_in) -> np.ndarray:
        """Structural inches -> body axes metres from the reference point. Accepts (..., 3)."""
        d = np.asarray(xyz_in, dtype=float) - np.asarray(self.origin_in)
        return d * np.array([-IN_TO_M, IN_TO_M, -IN_TO_M])

    def to_structural_in(self, r_body_m) -> np.ndarray:
        """Body axes metres from the reference point -> structural inches. Accepts (..., 3)."""
        r = np.asarray(r_body_m, dtype=float)
        return np.asarray(self.origin_in) + r * np.array([-1.0, 1.0, -1.0]) / IN_TO_M


def structural_frame(root_dir: Path, model: str, reference_point: str) -> StructuralFrame:
    """Read the named ``<location>`` (e.g. ``"VRP"``) of ``model`` as the body-axis origin."""
    path = Path(root_dir) / "aircraft" / model / f"{model}.xml"
    root = ET.parse(path).getroot()
    for loc in root.iter("location"):
        if loc.get("name") == reference_point:
            unit = (loc.get("unit") or "IN").upper()
            scale = {"IN": 1.0, "FT": 12.0, "M": 1.0 / IN_TO_M}.get(unit)
            if scale is None:
                raise ValueError(f"{path}: location {reference_point!r} has unknown unit {unit!r}")
            xyz = tuple(float(loc.findtext(a, "0")) * scale for a in "xyz")
            return StructuralFrame(origin_in=xyz)  # type: ignore[arg-type]
    raise ValueError(
        f"{path}: no <location name={reference_point!r}>; set reference_point in the airframe TOML "
        "to one of the model's named locations (e.g. VRP)"
    )


def create_fdm(
    model: str, planet: str, dt_s: float, reference_point: str = "VRP"
) -> tuple[jsbsim.FGFDMExec, StructuralFrame]:
    """Build an FDM for the patched ``model`` on a flat non-rotating planet or the WGS84 earth.

    Parameters
    ----------
    model : JSBSim aircraft name (``"f16"``).
    reference_point : name of the model's ``<location>`` that is the body-axis origin.
    planet : ``"flat"`` (flat, non-rotating, constant g, integrators 3/5/5/5) or ``"wgs84"``
        (JSBSim's default rotating ellipsoid with J2 gravity and default integrators).
    dt_s : integration step, s.

    Returns
    -------
    fdm and the structural frame of its reference point (the body-axis origin).
    """
    if planet not in ("flat", "wgs84"):
        raise ValueError(f"planet must be 'flat' or 'wgs84', got {planet!r}")
    if not (0.0 < dt_s <= 0.05):
        raise ValueError(f"dt_s must be in (0, 0.05] s, got {dt_s}; JSBSim models need >= 20 Hz")
    root = patched_root_dir(model)
    # JSBSim prints its banner to stdout when the first FGFDMExec of a process is built at a
    # debug level above 0. The level is a process-wide static (FGJSBBase::debug_lvl); setting it
    # first silences the banner in every process, pool workers included, without touching the
    # C-level stdout. (JSBSIM_DEBUG, if set, still overrides it during construction.)
    jsbsim.FGJSBBase().debug_lvl = 0
    fdm = jsbsim.FGFDMExec(str(root), None)
    fdm.set_debug_level(0)
    fdm.disable_output()
    if planet == "flat":
        # the planet must be loaded before the model: the model binds gravity to it
        if not fdm.load_planet(str(root / "flat_planet.xml"), False):
            raise RuntimeError(f"JSBSim refused the generated planet {root / 'flat_planet.xml'}")
    if not fdm.load_model(model):
        raise RuntimeError(f"JSBSim could not load model {model!r} from {root}")
    fdm.set_dt(dt_s)
    if planet == "flat":
        fdm["simulation/gravity-model"] = 0  # spherical GM/r^2, no J2
        for name, code in _INTEGRATORS_FLAT.items():
            fdm[name] = code
    return fdm, structural_frame(root, model, reference_point)


def set_mass(
    fdm: jsbsim.FGFDMExec,
    frame: StructuralFrame,
    fuel_kg: float,
    ballast_kg: float,
    r_ballast_body_m,
    *,
    n_internal_tanks: int = 2,
) -> None:
    """Load internal fuel (split equally over the first ``n_internal_tanks``) and the ballast.

    External tanks (index >= ``n_internal_tanks``) are emptied. Must be called before trimming.
    """
    pm = fdm.get_property_manager()
    n_tanks = 0
    while pm.get_node(f"propulsion/tank[{n_tanks}]/contents-lbs") is not None:
        n_tanks += 1
    if n_tanks < n_internal_tanks:
        raise ValueError(f"the model has {n_tanks} tanks, fewer than {n_internal_tanks} internal")
    per_tank_lbm = fuel_kg / LBM_TO_KG / n_internal_tanks
    for i in range(n_tanks):
        fdm[f"propulsion/tank[{i}]/contents-lbs"] = per_tank_lbm if i < n_internal_tanks else 0.0
    idx = ballast_index(fdm)
    xyz_in = frame.to_structural_in(r_ballast_body_m)
    fdm[f"inertia/pointmass-weight-lbs[{idx}]"] = ballast_kg / LBM_TO_KG
    for axis, v in zip("XYZ", xyz_in, strict=True):
        fdm[f"inertia/pointmass-location-{axis}-inches[{idx}]"] = float(v)


def ballast_index(fdm: jsbsim.FGFDMExec) -> int:
    """Index of the ``Ballast`` point mass (the last one; the patch appends it)."""
    i = 0
    pm = fdm.get_property_manager()
    while pm.get_node(f"inertia/pointmass-weight-lbs[{i + 1}]") is not None:
        i += 1
    return i


def set_initial_conditions(
    fdm: jsbsim.FGFDMExec,
    *,
    latitude_rad: float,
    longitude_rad: float,
    altitude_m: float,
    heading_rad: float,
    mach: float,
) -> None:
    """Set JSBSim initial conditions in still air: position first, then attitude, then speed.

    The order matters (SPEC §7): the speed conversion uses the atmosphere at the IC position.
    Steady wind is not an IC here: JSBSim 1.3.3's IC treats the wind with the opposite sign to
    its atmosphere model (an IC Mach of 0.6 in a 11 m/s tailwind flies at Mach 0.53), so
    :mod:`synth.flight` trims in still air and then restarts with :func:`set_body_velocity_ic`.
    """
    fdm["ic/lat-geod-rad"] = latitude_rad
    fdm["ic/long-gc-rad"] = longitude_rad
    fdm["ic/h-sl-ft"] = altitude_m / FT_TO_M
    fdm["ic/psi-true-rad"] = heading_rad
    fdm["ic/phi-rad"] = 0.0
    fdm["ic/gamma-rad"] = 0.0
    fdm["ic/vw-mag-fps"] = 0.0
    fdm["ic/mach"] = mach


def trim(fdm: jsbsim.FGFDMExec, nz: float | None = None) -> dict[str, float]:
    """Run JSBSim's full trim (or, given ``nz``, its pull-up trim) and return the residuals in SI.

    Parameters
    ----------
    fdm : the FDM, initial conditions set.
    nz : load factor to trim at (JSBSim's pull-up trim: wings level, a steady pitch rate; its
        achieved load factor is within about 0.01 of ``nz``); None for the full 1 g trim.

    Returns
    -------
    ``{"udot_mps2", "vdot_mps2", "wdot_mps2", "pdot_rps2", "qdot_rps2", "rdot_rps2", "mach"}``.

    Raises
    ------
    RuntimeError
        If JSBSim reports that the trim failed (its message is kept).
    """
    if nz is not None:
        fdm["ic/targetNlf"] = float(nz)
    try:
        fdm.do_trim(1 if nz is None else 3)  # FGTrim modes: 1 full, 3 pull-up
    except Exception as exc:  # JSBSim raises its own TrimFailureException
        raise RuntimeError(f"JSBSim trim failed: {exc}") from None
    out = {f"{a}dot_mps2": fdm[f"accelerations/{a}dot-ft_sec2"] * FT_TO_M for a in "uvw"}
    out.update({f"{a}dot_rps2": fdm[f"accelerations/{a}dot-rad_sec2"] for a in "pqr"})
    out["mach"] = fdm["velocities/mach"]
    return out


def lift_and_flap_coefficients(fdm: jsbsim.FGFDMExec) -> dict[str, float]:
    """The aerodynamic lift coefficient and the trailing-edge flaps' share of lift and drag.

    Returns
    -------
    ``{"cl", "cl_flap", "cd_flap", "flap_rad"}``: total lift coefficient (wind axes), the flap's
    lift and drag coefficients (the f16's ``aero/coefficient/CLDflaps`` and ``CDDflaps``, forces
    divided by dynamic pressure and wing area) and the symmetric flap deflection, rad, they use.
    """
    qs_lbf = fdm["aero/qbar-psf"] * fdm["metrics/Sw-sqft"]
    return {
        "cl": fdm["forces/fwz-aero-lbs"] / qs_lbf,
        "cl_flap": fdm["aero/coefficient/CLDflaps"] / qs_lbf,
        "cd_flap": fdm["aero/coefficient/CDDflaps"] / qs_lbf,
        "flap_rad": fdm["fcs/flaperon-mix-rad"],
    }


def start_engines(fdm: jsbsim.FGFDMExec) -> None:
    """Start every engine (JSBSim models start with engines off; the trim needs thrust)."""
    fdm["propulsion/set-running"] = -1


def freeze_fuel(fdm: jsbsim.FGFDMExec) -> None:
    """Stop the engines burning fuel (``propulsion/fuel_freeze``): the mass stays the loaded one."""
    fdm["propulsion/fuel_freeze"] = 1.0


def add_pitch_trim(fdm: jsbsim.FGFDMExec, stick_norm: float) -> None:
    """Move ``stick_norm`` (-1..1, the f16's ``fcs/elevator-cmd-norm`` units) into the pitch trim
    (``fcs/pitch-trim-cmd-norm``, summed with the stick at the FCS input): the pilot trims the
    stick force out, the stick returns to neutral with the same command."""
    fdm["fcs/pitch-trim-cmd-norm"] = fdm["fcs/pitch-trim-cmd-norm"] + stick_norm


def set_gear(fdm: jsbsim.FGFDMExec, down: bool) -> None:
    """Command the landing gear (the trim moves it to the commanded position at once)."""
    fdm["gear/gear-cmd-norm"] = 1.0 if down else 0.0


def set_body_velocity_ic(
    fdm: jsbsim.FGFDMExec, v_body_mps, euler_rad: tuple[float, float, float]
) -> None:
    """Set the IC attitude and earth-relative body velocity (with no IC wind), m/s, rad."""
    fdm["ic/vw-mag-fps"] = 0.0
    for name, val in zip(("ic/phi-rad", "ic/theta-rad", "ic/psi-true-rad"), euler_rad, strict=True):
        fdm[name] = float(val)
    for name, val in zip(("ic/u-fps", "ic/v-fps", "ic/w-fps"), v_body_mps, strict=True):
        fdm[name] = float(val) / FT_TO_M


class InputSetter:
    """Writes the pilot's five normalized inputs through pre-resolved property nodes."""

    _PROPS = (
        "fcs/elevator-cmd-norm",
        "fcs/aileron-cmd-norm",
        "fcs/rudder-cmd-norm",
        "fcs/throttle-cmd-norm",
        "fcs/speedbrake-cmd-norm",
    )

    def __init__(self, fdm: jsbsim.FGFDMExec) -> None:
        pm = fdm.get_property_manager()
        fdm["fcs/speedbrake-cmd-norm"] = 0.0  # make sure the node exists
        self._setters = [pm.get_node(p).set_double_value for p in self._PROPS]

    def set(
        self, elevator: float, aileron: float, rudder: float, throttle: float, speedbrake: float
    ) -> None:
        """Set elevator, aileron, rudder (-1..1), throttle and speedbrake (0..1) commands."""
        e, a, r, t, b = self._setters
        e(elevator)
        a(aileron)
        r(rudder)
        t(throttle)
        b(speedbrake)


def set_wind_ned(fdm: jsbsim.FGFDMExec, wind_ned_mps) -> None:
    """Set the steady wind, NED, m/s."""
    n, e, d = (float(x) / FT_TO_M for x in wind_ned_mps)
    fdm["atmosphere/wind-north-fps"] = n
    fdm["atmosphere/wind-east-fps"] = e
    fdm["atmosphere/wind-down-fps"] = d


def set_turbulence(
    fdm: jsbsim.FGFDMExec, *, severity: int, windspeed_at_20ft_mps: float, tustin: bool = True
) -> None:
    """Switch on JSBSim's MIL-F-8785C / MIL-HDBK-1797 turbulence (``severity`` 0 switches it off).

    Parameters
    ----------
    severity : probability-of-exceedance index 0..7 of JSBSim's milspec model (3 light,
        4 moderate, 6 severe).
    windspeed_at_20ft_mps : wind speed at 20 ft AGL that scales low-altitude turbulence, m/s.
    tustin : Tustin-discretized transfer functions (``turb-type`` 4) rather than the Dryden
        "milspec" form (3).
    """
    if severity <= 0:
        fdm["atmosphere/turb-type"] = 0
        return
    fdm["atmosphere/turb-type"] = 4 if tustin else 3
    fdm["atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps"] = windspeed_at_20ft_mps / FT_TO_M
    fdm["atmosphere/turbulence/milspec/severity"] = severity


def start_cosine_gust(
    fdm: jsbsim.FGFDMExec, *, amplitude_mps: float, direction_ned, duration_s: float
) -> None:
    """Start JSBSim's 1-cosine gust now: rises over ``duration_s``/2, falls over ``duration_s``/2."""
    fdm["atmosphere/cosine-gust/startup-duration-sec"] = duration_s / 2.0
    fdm["atmosphere/cosine-gust/steady-duration-sec"] = 0.0
    fdm["atmosphere/cosine-gust/end-duration-sec"] = duration_s / 2.0
    fdm["atmosphere/cosine-gust/magnitude-ft_sec"] = amplitude_mps / FT_TO_M
    fdm["atmosphere/cosine-gust/frame"] = 3  # eGustFrame::gfLocal, i.e. NED
    for axis, v in zip("XYZ", direction_ned, strict=True):
        fdm[f"atmosphere/cosine-gust/{axis}-velocity-ft_sec"] = float(v)
    fdm["atmosphere/cosine-gust/start"] = 1


# --- per-step state reading -----------------------------------------------------------------------
# (column name, JSBSim property, scale to SI). Columns with a frame conversion are fixed up in
# ``SampleReader.to_si`` (CG position) or in ``to_truth`` (specific force needs the mass).
_CHANNELS: tuple[tuple[str, str, float], ...] = (
    ("u_mps", "velocities/u-fps", FT_TO_M),
    ("v_mps", "velocities/v-fps", FT_TO_M),
    ("w_mps", "velocities/w-fps", FT_TO_M),
    ("u_air_mps", "velocities/u-aero-fps", FT_TO_M),
    ("v_air_mps", "velocities/v-aero-fps", FT_TO_M),
    ("w_air_mps", "velocities/w-aero-fps", FT_TO_M),
    ("wind_n_mps", "atmosphere/total-wind-north-fps", FT_TO_M),
    ("wind_e_mps", "atmosphere/total-wind-east-fps", FT_TO_M),
    ("wind_d_mps", "atmosphere/total-wind-down-fps", FT_TO_M),
    ("p_rps", "velocities/pi-rad_sec", 1.0),
    ("q_rps", "velocities/qi-rad_sec", 1.0),
    ("r_rps", "velocities/ri-rad_sec", 1.0),
    ("pdot_rps2", "accelerations/pidot-rad_sec2", 1.0),
    ("qdot_rps2", "accelerations/qidot-rad_sec2", 1.0),
    ("rdot_rps2", "accelerations/ridot-rad_sec2", 1.0),
    ("fx_n", "forces/fbx-total-lbs", LBF_TO_N),
    ("fy_n", "forces/fby-total-lbs", LBF_TO_N),
    ("fz_n", "forces/fbz-total-lbs", LBF_TO_N),
    ("phi_rad", "attitude/phi-rad", 1.0),
    ("theta_rad", "attitude/theta-rad", 1.0),
    ("psi_rad", "attitude/psi-rad", 1.0),
    ("h_m", "position/h-sl-ft", FT_TO_M),
    ("h_agl_m", "position/h-agl-ft", FT_TO_M),
    ("alpha_rad", "aero/alpha-rad", 1.0),
    ("beta_rad", "aero/beta-rad", 1.0),
    ("tas_mps", "velocities/vt-fps", FT_TO_M),
    ("mach", "velocities/mach", 1.0),
    ("p_static_pa", "atmosphere/P-psf", PSF_TO_PA),
    ("t_static_k", "atmosphere/T-R", RANKINE_TO_K),
    ("rho_kgpm3", "atmosphere/rho-slugs_ft3", SLUGFT3_TO_KGM3),
    ("qbar_pa", "aero/qbar-psf", PSF_TO_PA),
    ("gear_pos_norm", "gear/gear-pos-norm", 1.0),
    ("cg_x_m", "inertia/cg-x-in", 1.0),  # structural inches; converted in to_si
    ("cg_y_m", "inertia/cg-y-in", 1.0),
    ("cg_z_m", "inertia/cg-z-in", 1.0),
    ("mass_kg", "inertia/mass-slugs", SLUG_TO_KG),
    ("g_mps2", "accelerations/gravity-ft_sec2", FT_TO_M),
    ("elevator_pos_rad", "fcs/elevator-pos-rad", 1.0),
    ("aileron_left_pos_rad", "fcs/left-aileron-pos-rad", 1.0),
    ("aileron_right_pos_rad", "fcs/right-aileron-pos-rad", 1.0),
    ("rudder_pos_rad", "fcs/rudder-pos-rad", 1.0),
    ("lef_pos_rad", "fcs/lef-pos-deg", DEG_TO_RAD),
    ("throttle_pos_norm", "fcs/throttle-pos-norm", 1.0),
    ("elevator_cmd_norm", "fcs/elevator-cmd-norm", 1.0),
    ("aileron_cmd_norm", "fcs/aileron-cmd-norm", 1.0),
    ("rudder_cmd_norm", "fcs/rudder-cmd-norm", 1.0),
    ("throttle_cmd_norm", "fcs/throttle-cmd-norm", 1.0),
)

#: Column index of every channel in the raw and SI buffers.
COL: dict[str, int] = {name: i for i, (name, _, _) in enumerate(_CHANNELS)}
#: Columns copied into ``TruthTrajectory.controls``.
CONTROL_COLUMNS = (
    "elevator_pos_rad",
    "aileron_left_pos_rad",
    "aileron_right_pos_rad",
    "rudder_pos_rad",
    "lef_pos_rad",
    "throttle_pos_norm",
    "elevator_cmd_norm",
    "aileron_cmd_norm",
    "rudder_cmd_norm",
    "throttle_cmd_norm",
)


class SampleReader:
    """Reads every truth signal of an FDM once per step into a preallocated buffer.

    Property nodes are resolved once; each :meth:`read` is one ``get_double_value`` per channel
    (about 0.1 us each), so reading costs a few microseconds per step.

    Parameters
    ----------
    fdm : a loaded FGFDMExec.
    frame : structural frame of the reference point.
    """

    n_channels = len(_CHANNELS)

    def __init__(self, fdm: jsbsim.FGFDMExec, frame: StructuralFrame) -> None:
        pm = fdm.get_property_manager()
        nodes = []
        for name, prop, _ in _CHANNELS:
            node = pm.get_node(prop)
            if node is None:
                raise RuntimeError(f"JSBSim {JSBSIM_VERSION} has no property {prop!r} for {name}")
            nodes.append(node)
        self._getters = [n.get_double_value for n in nodes]
        self.frame = frame
        #: raw * scale + offset is SI (CG rows include the structural -> body shift)
        self.scale = np.array([s for _, _, s in _CHANNELS])
        self.offset = np.zeros(len(_CHANNELS))
        # CG: structural inches -> body metres from the reference point, per axis
        for axis, sign, origin in zip("xyz", (-1.0, 1.0, -1.0), frame.origin_in, strict=True):
            j = COL[f"cg_{axis}_m"]
            self.scale[j] = sign * IN_TO_M
            self.offset[j] = -sign * IN_TO_M * origin

    def read_raw(self) -> list[float]:
        """One sample of every channel in JSBSim units (list, in ``COL`` order)."""
        return [g() for g in self._getters]

    def read_si(self) -> np.ndarray:
        """One sample of every channel in SI (forces in N, not yet divided by mass)."""
        return np.asarray(self.read_raw()) * self.scale + self.offset

    def to_si(self, raw: np.ndarray) -> np.ndarray:
        """Convert a (N, n_channels) raw buffer to SI, vectorized."""
        return raw * self.scale + self.offset


def to_truth(
    si: np.ndarray, t_s: np.ndarray, *, planet: str, meta: dict | None = None
) -> TruthTrajectory:
    """Assemble a :class:`TruthTrajectory` from an SI buffer produced by :class:`SampleReader`.

    Parameters
    ----------
    si : (N, n_channels) SI buffer (``SampleReader.to_si`` of the raw rows).
    t_s : (N,) time since the start of the maneuver, s.
    planet : ``"flat"`` or ``"wgs84"``.
    meta : run facts to store.
    """

    def cols(*names: str) -> np.ndarray:
        return np.ascontiguousarray(si[:, [COL[n] for n in names]])

    mass_kg = si[:, COL["mass_kg"]].copy()
    force_n = cols("fx_n", "fy_n", "fz_n")
    return TruthTrajectory(
        t_s=np.asarray(t_s, dtype=float),
        v_body_mps=cols("u_mps", "v_mps", "w_mps"),
        v_air_body_mps=cols("u_air_mps", "v_air_mps", "w_air_mps"),
        wind_ned_mps=cols("wind_n_mps", "wind_e_mps", "wind_d_mps"),
        omega_body_rps=cols("p_rps", "q_rps", "r_rps"),
        omega_dot_body_rps2=cols("pdot_rps2", "qdot_rps2", "rdot_rps2"),
        specific_force_cg_body_mps2=force_n / mass_kg[:, None],
        euler_rad=cols("phi_rad", "theta_rad", "psi_rad"),
        h_m=si[:, COL["h_m"]].copy(),
        alpha_rad=si[:, COL["alpha_rad"]].copy(),
        beta_rad=si[:, COL["beta_rad"]].copy(),
        tas_mps=si[:, COL["tas_mps"]].copy(),
        mach=si[:, COL["mach"]].copy(),
        p_static_pa=si[:, COL["p_static_pa"]].copy(),
        t_static_k=si[:, COL["t_static_k"]].copy(),
        rho_kgpm3=si[:, COL["rho_kgpm3"]].copy(),
        qbar_pa=si[:, COL["qbar_pa"]].copy(),
        gear_pos_norm=si[:, COL["gear_pos_norm"]].copy(),
        r_cg_body_m=cols("cg_x_m", "cg_y_m", "cg_z_m"),
        mass_kg=mass_kg,
        g_mps2=si[:, COL["g_mps2"]].copy(),
        controls={c: si[:, COL[c]].copy() for c in CONTROL_COLUMNS},
        planet=planet,
        meta=dict(meta or {}),
    )
