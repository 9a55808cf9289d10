"""The one table of FMU variables.

`lss_fmu.build` generates both `modelDescription.xml` and the C header
(`lss_vars.h`: value-reference enum, the parameter and output structs and a
descriptor table) from this list, so the XML and the C code cannot drift.
`min` and `max` are closed ranges, and they are the ranges the FMU enforces:
the C side checks every parameter and input against this table
(chain_check_params); only rules that depend on the layout (a cart index
below the number of carts, a bump inside the track) are checked on top.
Value references are positions in the list (starting at 1): append new
variables at the end of their group to keep existing references stable.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Union

Number = Union[int, float, bool, str]


@dataclass(frozen=True)
class Var:
    name: str
    type: str                 # Real | Integer | Boolean | String
    causality: str            # parameter | calculatedParameter | input | output
    variability: str          # fixed | tunable | continuous | discrete
    description: str
    unit: Optional[str] = None
    start: Optional[Number] = None
    min: Optional[float] = None
    max: Optional[float] = None
    bulk: bool = False        # an output filled by a walk over every cart or motor group: the FMU fills
                              # it only when it (or a state) is asked for, not at every communication point

    @property
    def field(self) -> str:
        """C struct field name: dots become underscores."""
        return self.name.replace(".", "_")

    @property
    def in_params(self) -> bool:
        """Parameters and inputs live in LSSParams (set by the master);
        outputs and calculated parameters in LSSOutputs (set by the model)."""
        return self.causality in ("parameter", "input")


P, CP, IN, OUT = "parameter", "calculatedParameter", "input", "output"
N_GROUPS = 8   # motor groups a plant model can drive (drive.n_groups <= N_GROUPS)
N_LOAD_PORTS = 2   # item ports (an induction and a chute)
N_SENS = 10        # forward sensitivities at most (the design vector's length)


def sensitivity_output(k: int, channel: str) -> str:
    """The output holding the derivative of force `channel` by the k-th sensitivity's parameter (k from 1)."""
    return f"sensitivity.p{k}.{channel.split('.', 1)[1]}"


FORCE_CHANNELS = [
    "transducer.joint.F_x", "transducer.joint.F_y", "transducer.joint.F_z",
    "transducer.steering.F_left", "transducer.steering.F_right",
    "transducer.driving.F_left", "transducer.driving.F_right",
]

VARIABLES: list[Var] = [
    # --- layout and configuration -------------------------------------------------
    Var("layout.name", "String", P, "fixed",
        "built-in layout (layout1..layout7, demo, oval) or path to a layout file",
        start="demo"),
    Var("contact.model", "Integer", P, "fixed",
        "hysteresis damping law: 1 HC, 2 HW, 3 LW, 4 LN, 5 GZ (exact), 6 FL",
        start=3, min=1, max=6),
    Var("contact.e_JA", "Real", P, "tunable", "coefficient of restitution, joint axial",
        "1", 0.5, 1e-3, 1.0),
    Var("contact.e_JR", "Real", P, "tunable", "coefficient of restitution, joint radial",
        "1", 0.5, 1e-3, 1.0),
    Var("contact.e_SW", "Real", P, "tunable", "coefficient of restitution, steering wheel",
        "1", 0.5, 1e-3, 1.0),
    Var("contact.e_RW", "Real", P, "tunable", "coefficient of restitution, driving wheel",
        "1", 0.5, 1e-3, 1.0),
    Var("contact.v_min", "Real", P, "fixed",
        "floor of the impact velocity v_i (contacts closed from the start use it)",
        "m/s", 0.05, 1e-6, 10.0),
    Var("chain.pretension", "Real", P, "fixed",
        "pretension d: total stretch of the chain against the track loop", "m", 0.01, -0.5, 0.5),
    Var("wheel.mu_roll", "Real", P, "tunable", "rolling resistance coefficient mu_d",
        "1", 0.015, 0.0, 0.5),
    Var("drive.Kp", "Real", P, "tunable", "proportional gain of the speed controller (thrust per motor)",
        "N.s/m", 500.0, 0.0, 1e9),
    Var("drive.Ki", "Real", P, "tunable", "integral gain of the speed controller (thrust per motor)",
        "N/m", 200.0, 0.0, 1e9),
    Var("drive.F_max", "Real", P, "fixed", "thrust saturation of one linear motor",
        "N", 400.0, 0.0, 1e7),
    Var("drive.motor_length", "Real", P, "fixed", "active length of one linear motor",
        "m", 0.6, 1e-3, 20.0),
    Var("drive.v_ref", "Real", IN, "continuous", "chain speed reference v_s",
        "m/s", 2.0, -20.0, 20.0),
    Var("cart.mass_factor", "Real", P, "fixed",
        "scales the cart mass and inertia of the layout's cart type", "1", 1.0, 1e-3, 20.0),
    Var("track.guide_gap", "Real", P, "fixed",
        "lateral play of each steering wheel against its guide face (negative: preload)",
        "m", 0.0005, -0.005, 0.05),
    Var("chain.v_init", "Real", P, "fixed",
        "initial chain speed (negative: start at drive.v_ref)", "m/s", -1.0, -20.0, 20.0),
    Var("chain.transducer", "Integer", P, "fixed",
        "index of the transducer cart in the chain (0 = first cart)", start=0, min=0),
    Var("solver.tolerance", "Real", P, "fixed",
        "relative tolerance of the embedded Runge-Kutta pair (fmi2SetupExperiment overrides)",
        "1", 1e-4, 1e-12, 0.1),
    Var("solver.h_max", "Real", P, "fixed", "largest internal step", "s", 0.01, 1e-6, 1.0),
    # --- transducer cart ----------------------------------------------------------
    Var("transducer.joint.F_x", "Real", OUT, "continuous",
        "front-joint force on the transducer cart, cart x (forward; positive = tension)", "N"),
    Var("transducer.joint.F_y", "Real", OUT, "continuous",
        "front-joint force on the transducer cart, cart y (left)", "N"),
    Var("transducer.joint.F_z", "Real", OUT, "continuous",
        "front-joint force on the transducer cart, cart z (up)", "N"),
    Var("transducer.steering.F_left", "Real", OUT, "continuous",
        "left steering-wheel lateral contact force", "N"),
    Var("transducer.steering.F_right", "Real", OUT, "continuous",
        "right steering-wheel lateral contact force", "N"),
    Var("transducer.driving.F_left", "Real", OUT, "continuous",
        "left driving-wheel vertical contact force", "N"),
    Var("transducer.driving.F_right", "Real", OUT, "continuous",
        "right driving-wheel vertical contact force", "N"),
    Var("transducer.wheel.w_sl", "Real", OUT, "continuous", "left steering-wheel speed", "rad/s"),
    Var("transducer.wheel.w_sr", "Real", OUT, "continuous", "right steering-wheel speed", "rad/s"),
    Var("transducer.wheel.w_dl", "Real", OUT, "continuous", "left driving-wheel speed", "rad/s"),
    Var("transducer.wheel.w_dr", "Real", OUT, "continuous", "right driving-wheel speed", "rad/s"),
    Var("transducer.s", "Real", OUT, "continuous",
        "arc-length position of the transducer cart's wheel axle on the track", "m"),
    # --- chain and drive -----------------------------------------------------------
    Var("chain.v_mean", "Real", OUT, "continuous", "mean tangential speed of the chain", "m/s"),
    Var("drive.F_total", "Real", OUT, "continuous", "total thrust of all linear motors", "N"),
    Var("drive.P_total", "Real", OUT, "continuous", "total mechanical power of all linear motors", "W"),
    Var("drive.F_cmd", "Real", OUT, "continuous",
        "controller thrust command per motor after saturation", "N"),
    # --- energy bookkeeping (checks and plant-level use) ---------------------------
    Var("energy.E_mech", "Real", OUT, "continuous",
        "kinetic + gravitational + elastic contact energy of the chain", "J", bulk=True),
    Var("energy.W_motor", "Real", OUT, "continuous", "work done by the motors since start", "J"),
    Var("energy.W_damping", "Real", OUT, "continuous",
        "energy dissipated by contact hysteresis since start", "J"),
    Var("energy.W_rolling", "Real", OUT, "continuous",
        "energy dissipated by rolling resistance since start", "J"),
    # --- solver statistics ------------------------------------------------------
    Var("solver.n_steps", "Integer", OUT, "discrete", "accepted internal steps since start"),
    Var("solver.n_rejected", "Integer", OUT, "discrete", "rejected internal steps since start"),
    Var("solver.h_last", "Real", OUT, "discrete", "last accepted internal step", "s"),
    Var("solver.n_rhs", "Integer", OUT, "discrete", "right-hand-side evaluations since start"),
    # --- calculated from layout and parameters -----------------------------------
    Var("chain.n_carts", "Integer", CP, "fixed", "number of carts in the chain"),
    Var("track.length", "Real", CP, "fixed", "length of the closed track", "m"),
    Var("cart.mass", "Real", CP, "fixed", "mass of one cart", "kg"),
    Var("chain.pitch", "Real", CP, "fixed", "unstretched joint-to-joint length of one cart", "m"),
    Var("chain.preload", "Real", CP, "fixed",
        "joint axial preload from the pretension, K_a (d/N)^n", "N"),
    Var("drive.n_motors", "Integer", CP, "fixed", "number of linear motors"),
    # --- effects catalogue (issue 7; docs/effects.md): all off by default --------------
    Var("effects.wheel_oor.amplitude", "Real", P, "fixed",
        "radial runout a of the two driving wheels of one cart: r = r0 + a cos(k theta - phi)",
        "m", 0.0, 0.0, 0.005),
    Var("effects.wheel_oor.order", "Integer", P, "fixed",
        "number of lobes k of the out-of-round driving wheels (1 = eccentric)", start=1, min=1, max=8),
    Var("effects.wheel_oor.phase_left", "Real", P, "fixed",
        "phase phi of the left out-of-round driving wheel (theta = 0 as assembled)", "rad", 0.0),
    Var("effects.wheel_oor.phase_right", "Real", P, "fixed",
        "phase phi of the right out-of-round driving wheel (theta = 0 as assembled)", "rad", 0.0),
    Var("effects.wheel_oor.cart", "Integer", P, "fixed",
        "cart with the out-of-round driving wheels (-1 = the transducer cart)", start=-1, min=-1),
    Var("effects.track_bump.height", "Real", P, "fixed",
        "height H of the cosine bump on the driving-wheel running surface", "m", 0.0, -0.005, 0.005),
    Var("effects.track_bump.s", "Real", P, "fixed",
        "arc-length position s_b of the bump centre, in [0, track length)", "m", 0.0, 0.0, 1e9),
    Var("effects.track_bump.length", "Real", P, "fixed", "length l of the bump",
        "m", 0.2, 1e-3, 5.0),
    Var("effects.joint_clearance.gap", "Real", P, "fixed",
        "play in every cart-to-cart joint: dead band on the axial and radial penetration",
        "m", 0.0, 0.0, 0.005),
    Var("effects.motor_ripple.amplitude", "Real", P, "fixed",
        "thrust ripple amplitude A of every linear motor (independent of the controller)",
        "N", 0.0, 0.0, 1000.0),
    Var("effects.motor_ripple.pitch", "Real", P, "fixed", "thrust ripple period p (pole pitch)",
        "m", 0.1, 1e-3, 2.0),
    Var("effects.motor_ripple.phase", "Real", P, "fixed", "thrust ripple phase phi", "rad", 0.0),
    Var("effects.resistance.c1", "Real", P, "fixed",
        "linear running resistance per cart, F = -(c1 v + c2 v |v|)", "N.s/m", 0.0, 0.0, 1e6),
    Var("effects.resistance.c2", "Real", P, "fixed",
        "quadratic (air drag) running resistance per cart", "N.s2/m2", 0.0, 0.0, 1e6),
    *[Var(f"effects.sensor.gain.{ch[len('transducer.'):]}", "Real", P, "fixed",
          f"relative gain error g of the {ch} channel: output = (1+g) F + o",
          "1", 0.0, -0.5, 0.5) for ch in FORCE_CHANNELS],
    *[Var(f"effects.sensor.offset.{ch[len('transducer.'):]}", "Real", P, "fixed",
          f"offset o of the {ch} channel: output = (1+g) F + o", "N", 0.0, -1e4, 1e4) for ch in FORCE_CHANNELS],
    Var("effects.mass.transducer_factor", "Real", P, "fixed",
        "the transducer cart's mass and inertia times this factor (on top of cart.mass_factor)",
        "1", 1.0, 0.2, 5.0),
    Var("effects.mass.spread", "Real", P, "fixed",
        "relative standard deviation of the other carts' masses (seeded, clipped at 3 sigma)",
        "1", 0.0, 0.0, 0.3),
    Var("effects.mass.seed", "Integer", P, "fixed", "seed of the cart mass spread", start=0, min=0),
    Var("transducer.v", "Real", OUT, "continuous", "tangential speed of the transducer cart's axle", "m/s"),
    Var("transducer.joint.v_axial", "Real", OUT, "continuous",
        "axial relative velocity at the transducer cart's front joint (closing positive)", "m/s"),
    Var("cart.r_drive", "Real", CP, "fixed", "rolling radius r0 of the driving wheels", "m"),
    # --- start from rest (measurement protocols, issue 17) ------------------------------
    Var("chain.s_start", "Real", P, "fixed",
        "arc-length position of cart 0's axle as the chain is assembled, in [0, track length)",
        "m", 0.0, 0.0, 1e6),
    Var("chain.relax_time", "Real", P, "fixed",
        "a chain that starts at rest (initial speed 0) first relaxes into its static equilibrium for this "
        "long (drive off, viscous damping), before t = 0; 0: it starts as assembled",
        "s", 0.0, 0.0, 10.0),
    # --- issue 19: the vectorised right-hand side and the 8th-order pair ------------------
    Var("solver.vector_path", "Integer", P, "fixed",
        "right-hand-side code path: 0 auto (the widest this CPU runs), 1 scalar, 2 AVX2, 3 AVX-512; "
        "a path the CPU or the build lacks falls back to the next narrower one (see solver.vector_path_used)",
        start=0, min=0, max=3),
    Var("solver.method", "Integer", P, "fixed",
        "embedded Runge-Kutta pair: 0 Dormand-Prince 5(4), 1 Dormand-Prince 8(5,3) (DOP853)",
        start=0, min=0, max=1),
    Var("solver.vector_path_used", "Integer", CP, "fixed",
        "right-hand-side code path in use: 1 scalar, 2 AVX2, 3 AVX-512"),
    # --- issue 52: the chain in a plant model (inputs a system model drives, outputs it reads) -------
    Var("drive.mode", "Integer", P, "fixed",
        "0: the internal PI speed controller commands every motor (drive.v_ref, drive.Kp, drive.Ki); "
        "1: external: each motor group's thrust is an input (drive.groupK.F), the PI is off",
        start=0, min=0, max=1),
    Var("drive.n_groups", "Integer", P, "fixed",
        "motor groups: the motors in track order, split into this many groups of (nearly) equal count; "
        "at most the number of motors", start=1, min=1, max=N_GROUPS),
    *[Var(f"drive.group{k}.F", "Real", IN, "continuous",
          f"external mode: thrust of each motor of group {k} on a plate it fully covers; "
          "saturated at +-drive.F_max (logged)", "N", 0.0, -1e6, 1e6) for k in range(1, N_GROUPS + 1)],
    *[v for k in range(1, N_GROUPS + 1) for v in (
        Var(f"drive.group{k}.F_total", "Real", OUT, "continuous",
            f"thrust the motors of group {k} apply to the chain (the groups sum to drive.F_total)", "N", bulk=True),
        Var(f"drive.group{k}.v", "Real", OUT, "continuous",
            f"tangential speed of the chain over group {k}'s motors (plates weighted by their coverage; "
            "0 where no plate covers them)", "m/s", bulk=True),
        Var(f"drive.group{k}.P", "Real", OUT, "continuous",
            f"power of group {k}'s thrust (its plates' thrust times their tangential speed)", "W", bulk=True))],
    Var("chain.joint.F_max", "Real", OUT, "continuous",
        "largest joint force in the chain (axial and radial together)", "N", bulk=True),
    Var("chain.joint.F_max_cart", "Integer", OUT, "discrete",
        "the cart whose front joint carries chain.joint.F_max", bulk=True),
    Var("station.induction.s", "Real", P, "fixed",
        "arc position of the induction station (where items are put on carts), in [0, track length)",
        "m", 0.0, 0.0, 1e6),
    Var("station.chute.s", "Real", P, "fixed",
        "arc position of the chute (where items leave their carts), in [0, track length)", "m", 0.0, 0.0, 1e6),
    Var("station.induction.cart", "Integer", OUT, "discrete",
        "the cart whose axle passed the induction station last (changes as the next cart passes)", bulk=True),
    Var("station.chute.cart", "Integer", OUT, "discrete",
        "the cart whose axle passed the chute last", bulk=True),
    *[v for k in range(1, N_LOAD_PORTS + 1) for v in (
        Var(f"load{k}.cart", "Integer", IN, "discrete",
            f"item port {k}: the cart it loads (-1: idle); when the port's cart or mass changes, that cart "
            f"carries load{k}.mass from then on", start=-1, min=-1),
        Var(f"load{k}.mass", "Real", IN, "discrete",
            f"item port {k}: the item mass on load{k}.cart (0: none); an item put on arrives with no speed "
            "(the cart shares its momentum with it), one taken off leaves at the cart's speed",
            "kg", 0.0, 0.0, 1000.0))],
    Var("chain.items.mass", "Real", OUT, "discrete", "mass of all items on the carts", "kg", bulk=True),
    Var("energy.E_items", "Real", OUT, "continuous",
        "mechanical energy the item ports changed (the inelastic loss of an item put on a moving cart, "
        "the items' weight): E_mech - E_items - W_motor + W_damping + W_rolling stays constant", "J"),
    # --- issue 50: forward sensitivities of the force channels -------------------------------------
    Var("sensitivity.n", "Integer", P, "fixed",
        "forward sensitivities: how many parameters to differentiate the force channels by (0: none); "
        "each is a follower chain that takes the solver's steps of the chain itself, its parameter moved by "
        "sensitivity.pK.step, so that sensitivity.pK.<channel> is free of the step-size control's noise",
        start=0, min=0, max=N_SENS),
    *[Var(f"sensitivity.p{k}.vr", "Integer", P, "fixed",
          f"the value reference of the Real parameter the {k}-th sensitivity is taken by (a parameter, "
          "not an input)", start=0, min=0) for k in range(1, N_SENS + 1)],
    *[Var(f"sensitivity.p{k}.step", "Real", P, "fixed",
          f"the {k}-th parameter's difference step, in its unit (either sign, not 0; the moved value must "
          "lie in the parameter's range)", start=1e-6, min=-1e6, max=1e6) for k in range(1, N_SENS + 1)],
    *[Var(sensitivity_output(k, c), "Real", OUT, "continuous",
          f"derivative of {c} by the {k}-th sensitivity's parameter, per unit of that parameter")
      for k in range(1, N_SENS + 1) for c in FORCE_CHANNELS],
]

BY_NAME = {v.name: v for v in VARIABLES}


def value_reference(name: str) -> int:
    return VARIABLES.index(BY_NAME[name]) + 1


CONTACT_MODELS = {"HC": 1, "HW": 2, "LW": 3, "LN": 4, "GZ": 5, "FL": 6}
SPEED_CHANNELS = [
    "transducer.wheel.w_sl", "transducer.wheel.w_sr",
    "transducer.wheel.w_dl", "transducer.wheel.w_dr",
]
