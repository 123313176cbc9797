"""The true generating unit: machine, exciter, PSS, governor and the hidden effects, as one
explicit ODE driven either by a Thevenin grid (whose source carries the event) or by a played-back
terminal voltage.

Written from /work/shared/reference/models.md (OpenIPSL/PSS/E conventions), independently of
the project's Rust engine:

* machines GENSAE (section 5: exponential saturation on |psi''|, both axes) and GENSAL (section 4:
  quadratic saturation on E'q, d-axis only); stator at omega = 1 (section 1.3); swing of section 3;
* exciters SEXS (9.1) and ESST1A (IEEE 421.5 ST1A as PSS/E: transducer, error limits, two
  lead-lags, non-windup regulator, field-current limiter, bus-fed ceiling V_t VRMAX - KC XadIfd);
* PSS STAB3 (9.2.1, on P_elec with P_REF frozen) and IEEEST (9.2.3, on speed, filter bypassed);
* governor HYGOV (9.3.1, velocity limit on dc/dt, c non-windup in [GMIN, GMAX]);
* the extensions of section 12 (two-mass shaft, speed deadband, bus-fed/constant ceilings,
  inverse-time OEL at the summing point) and the effects outside the catalog (see `EFFECTS`).

Per unit on the machine base throughout; the system base only at the measurement.
Non-windup limits freeze the state's derivative when the state is at or beyond the limit and
pushes outward; outputs are clamped."""

from __future__ import annotations

import cmath
import math

import numpy as np

TWO_PI = 2.0 * math.pi


def se_exp(psi: float, s10: float, s12: float) -> float:
    """GENSAE exponential saturation factor (models.md section 2)."""
    if psi <= 0.0 or s10 <= 0.0:
        return 0.0
    n = math.log(s12 / s10) / math.log(1.2)
    return s10 * psi**n


def quad_consts(s10: float, s12: float):
    """(A, B) of the GENSAL/GENROU quadratic saturation through (1.0, S10), (1.2, S12)."""
    if s10 <= 0.0:
        return None
    a = math.sqrt(s10 * 1.0 / (s12 * 1.2))
    A = 1.2 + 0.2 / (a - 1.0)
    B = 1.2 * s12 * (a - 1.0) ** 2 / 0.2**2
    return A, B


def se_quad(psi: float, ab) -> float:
    if ab is None or psi <= 0.0:
        return 0.0
    A, B = ab
    if psi <= A:
        return 0.0
    return B * (psi - A) ** 2 / psi


def exc_sat_quad(e: float, e1: float, se1: float, e2: float, se2: float) -> float:
    """Exciter saturation S_E(E) of a rotating exciter: B (E - A)^2 / E through (E1, SE1),
    (E2, SE2) (the PSS/E quadratic form)."""
    if se1 <= 0.0 or e <= 0.0:
        return 0.0
    r = math.sqrt(se1 * e1 / (se2 * e2))
    A = (e1 - r * e2) / (1.0 - r)
    B = se2 * e2 / (e2 - A) ** 2
    if e <= A:
        return 0.0
    return B * (e - A) ** 2 / e


def nonwindup(x: float, f: float, lo: float, hi: float) -> float:
    if (x >= hi and f > 0.0) or (x <= lo and f < 0.0):
        return 0.0
    return f


def clamp(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else (hi if x > hi else x)


def deadband(u: float, db: float) -> float:
    """Intentional deadband without jump (models.md 12.2, type 1)."""
    if u > db:
        return u - db
    if u < -db:
        return u + db
    return 0.0


class InitError(ValueError):
    """The operating point is infeasible for the unit (a limit violated at the start)."""


class TrueUnit:
    """One unit with its effects. `spec` holds `machine`, `exciter`, `pss` (or None),
    `governor` (PSS/E names), `ext` (effects inside the unit) and `mc` (measurement chain:
    terminal load, skew, voltage ratio), with `machine_mva`, `fn_hz` and `system_mva`."""

    def __init__(self, spec: dict):
        self.spec = spec
        self.mva = float(spec["machine_mva"])
        self.sys_mva = float(spec["system_mva"])
        self.fn = float(spec["fn_hz"])
        self.wb = TWO_PI * self.fn
        m = spec["machine"]
        self.mmodel = m["model"]
        assert self.mmodel in ("GENSAE", "GENSAL")
        self.m = {k: float(v) for k, v in m.items() if k != "model"}
        mm = self.m
        self.K3d = (mm["Xppd"] - mm["Xl"]) / (mm["Xpd"] - mm["Xl"])
        self.K4d = (mm["Xpd"] - mm["Xppd"]) / (mm["Xpd"] - mm["Xl"])
        self.K1d = (mm["Xpd"] - mm["Xppd"]) * (mm["Xd"] - mm["Xpd"]) / (mm["Xpd"] - mm["Xl"]) ** 2
        self.gamma = (mm["Xq"] - mm["Xl"]) / (mm["Xd"] - mm["Xl"])
        self.qab = quad_consts(mm["S10"], mm["S12"]) if self.mmodel == "GENSAL" else None
        e = spec["exciter"]
        self.emodel = e["model"]
        assert self.emodel in ("SEXS", "ESST1A")
        self.e = {k: float(v) for k, v in e.items() if k != "model"}
        p = spec.get("pss")
        self.pmodel = None
        if p is not None and p.get("in_service", True):
            self.pmodel = p["model"]
            assert self.pmodel in ("STAB3", "IEEEST")
            self.p = {k: float(v) for k, v in p.items() if k not in ("model", "in_service")}
        g = spec["governor"]
        assert g["model"] == "HYGOV"
        self.g = {k: float(v) for k, v in g.items() if k != "model"}
        self.ext = spec.get("ext", {}) or {}
        self.mc = spec.get("mc", {}) or {}
        # Terminal load (constant impedance inside the PMU current measurement), machine base:
        # S_L = conj(Y_L)|V|^2 -> Y_L = P_L - jQ_L.
        scale = self.sys_mva / self.mva
        self.yl = complex(self.mc.get("load_P", 0.0) * scale, -self.mc.get("load_Q", 0.0) * scale)
        self.offsets = [0.0, 0.0]  # (dVref, dnref) added after initialisation
        self.torque_noise = None  # a callable of t when the shaft carries hydraulic noise
        self.agc = None  # a callable of t: the gate set-point change
        self._layout()

    # ------------------------------------------------------------------ layout
    def _layout(self):
        names = ["delta", "dw", "Epq", "psikd", "Eppd"]
        ext = self.ext
        self.has_shaft = "shaft" in ext
        if self.has_shaft:
            names += ["dwt", "ths"]
        self.rot = "rotating_exciter" in ext
        if self.emodel == "SEXS":
            names += ["xLL", "xE"]
            if self.rot:
                names += ["efdx"]
        else:
            names += ["vm", "ll1", "ll2", "va", "xf"]
        if self.pmodel == "STAB3":
            names += ["pf", "x2", "x3"]
        elif self.pmodel == "IEEEST":
            names += ["l1", "l2", "wo"]
        self.pen_n = int(ext["penstock"]["sections"]) if "penstock" in ext else 0
        names += ["e", "c", "g"]
        if self.pen_n:
            names += [f"q{k}" for k in range(self.pen_n)] + [f"h{k}" for k in range(self.pen_n)]
        else:
            names += ["q"]
        self.has_backlash = "backlash" in ext
        if self.has_backlash:
            names += ["gy"]
        self.has_oel = "oel" in ext
        if self.has_oel:
            names += ["oelA", "oelV"]
        self.has_plantq = "plant_q" in ext
        if self.has_plantq:
            names += ["pqf", "pqx"]
        self.has_vhz = "vhz" in ext
        if self.has_vhz:
            names += ["vhzx"]
        self.has_scl = "scl" in ext
        if self.has_scl:
            names += ["sclA", "sclx"]
        self.names = names
        self.ix = {n: i for i, n in enumerate(names)}
        self.n = len(names)

    # ------------------------------------------------------------------ machine helpers
    def _stator_playback(self, Eppq, Eppd, vd, vq):
        m = self.m
        Ra, Xd2, Xq2 = m["R_a"], m["Xppd"], m["Xppq"]
        den = Ra * Ra + Xd2 * Xq2
        i_d = (Ra * (Eppd - vd) + Xq2 * (Eppq - vq)) / den
        i_q = (Xd2 * (vd - Eppd) + Ra * (Eppq - vq)) / den
        return i_d, i_q

    def _sat(self, Epq, Eppq, Eppd):
        m = self.m
        if self.mmodel == "GENSAE":
            return se_exp(math.hypot(Eppq, Eppd), m["S10"], m["S12"])
        return se_quad(Epq, self.qab)

    # ------------------------------------------------------------------ initialisation
    def init(self, P, Q, V0, th0, dw0=0.0):
        """Steady state at the machine terminal: P, Q (machine base, generator convention, at
        the machine, i.e. before any terminal load), |V0|, angle th0 (rad), speed dw0 (pu).
        Returns the state vector and sets the references."""
        m = self.m
        Ra, Xd, Xq, Xpd, Xppd, Xppq, Xl = (m[k] for k in ("R_a", "Xd", "Xq", "Xpd", "Xppd", "Xppq", "Xl"))
        V = cmath.rect(V0, th0)
        I = ((P + 1j * Q) / V).conjugate()
        if self.mmodel == "GENSAL":
            delta = cmath.phase(V + (Ra + 1j * Xq) * I)
        else:
            psi = V + (Ra + 1j * Xppd) * I
            Se0 = se_exp(abs(psi), m["S10"], m["S12"])
            th_psi = cmath.phase(psi)
            alpha = th_psi - cmath.phase(I)
            a = abs(psi) * (1 + self.gamma * Se0)
            b = abs(I) * (Xppd - Xq)
            delta = th_psi - math.atan2(b * math.cos(alpha), a - b * math.sin(alpha))

            # Newton on r(delta) (models.md 5.2 step 5; exact with X''q = X''d already).
            def r(d):
                vd = V0 * math.sin(d - th0)
                vq = V0 * math.cos(d - th0)
                idq = (I * cmath.exp(-1j * d)) * 1j
                i_d, i_q = idq.real, idq.imag
                Eq2 = vq + Xppd * i_d + Ra * i_q
                Ed2 = vd - Xppq * i_q + Ra * i_d
                se = se_exp(math.hypot(Eq2, Ed2), m["S10"], m["S12"])
                return Ed2 * (1 + self.gamma * se) - (Xq - Xppq) * i_q

            for _ in range(30):
                f = r(delta)
                if abs(f) < 1e-15:
                    break
                h = 1e-7
                delta -= f / ((r(delta + h) - r(delta - h)) / (2 * h))
        vd = V0 * math.sin(delta - th0)
        vq = V0 * math.cos(delta - th0)
        idq = 1j * I * cmath.exp(-1j * delta)
        i_d, i_q = idq.real, idq.imag
        Eppq = vq + Xppd * i_d + Ra * i_q
        Eppd = vd - Xppq * i_q + Ra * i_d
        Epq = Eppq + (Xpd - Xppd) * i_d
        psikd = Epq - (Xpd - Xl) * i_d
        if self.mmodel == "GENSAE":
            Se0 = se_exp(math.hypot(Eppq, Eppd), m["S10"], m["S12"])
            Efd0 = Epq + (Xd - Xpd) * i_d + Se0 * Eppq
        else:
            Efd0 = (1 + se_quad(Epq, self.qab)) * Epq + (Xd - Xpd) * i_d
        psid = Eppq - Xppd * i_d
        psiq = -Eppd - Xppq * i_q
        Te0 = psid * i_q - psiq * i_d
        D = m["D"]
        Pm0 = (1 + dw0) * Te0 + D * dw0
        self.Efd0, self.XadIfd0, self.Pm0, self.Te0 = Efd0, Efd0, Pm0, Te0
        self.Vt0, self.dw0 = V0, dw0
        self.I0 = I
        self.P0e = vd * i_d + vq * i_q
        x = [0.0] * self.n
        ix = self.ix
        x[ix["delta"]] = delta
        x[ix["dw"]] = dw0
        x[ix["Epq"]] = Epq
        x[ix["psikd"]] = psikd
        x[ix["Eppd"]] = Eppd
        ext = self.ext
        if self.has_shaft:
            sh = ext["shaft"]
            H = m["H"]
            Ht = sh["Ht_frac"] * H
            Hg = H - Ht
            Ks = (TWO_PI * sh["f_tor_hz"]) ** 2 * 2 * Ht * Hg / (self.wb * (Ht + Hg))
            wn = TWO_PI * sh["f_tor_hz"]
            Ds = 2 * sh["zeta"] * wn * 2 * Ht * Hg / (Ht + Hg)
            self.Ht, self.Hg, self.Ks, self.Ds = Ht, Hg, Ks, Ds
            Tm0 = Pm0 / (1 + dw0)
            x[ix["dwt"]] = dw0
            x[ix["ths"]] = Tm0 / Ks
        # ---- exciter
        e = self.e
        self.voel0 = 0.0
        if self.emodel == "SEXS":
            if self.rot:
                rx = ext["rotating_exciter"]
                se = exc_sat_quad(Efd0, rx["E1"], rx["SE1"], rx["E2"], rx["SE2"])
                self.rot_ke = 1.0 - se
                vr0 = (self.rot_ke + se) * Efd0
                x[ix["efdx"]] = Efd0
            else:
                vr0 = Efd0
            lo, hi = self._sexs_limits(V0, Efd0)
            if not (lo <= vr0 <= hi):
                raise InitError(f"E_fd0 {vr0:.4f} outside the exciter limits [{lo:.3f}, {hi:.3f}]")
            x[ix["xE"]] = vr0
            x[ix["xLL"]] = vr0 / e["K"]
            self.Vref = V0 + vr0 / e["K"]
        else:
            klr = e["KLR"] * max(0.0, self.XadIfd0 - e["ILR"])
            va0 = Efd0 + klr
            lo, hi = V0 * e["VRMIN"], V0 * e["VRMAX"] - e["KC"] * self.XadIfd0
            if not (lo <= Efd0 <= hi):
                raise InitError(f"E_fd0 {Efd0:.4f} outside the ESST1A ceiling [{lo:.3f}, {hi:.3f}]")
            if not (e["VAMIN"] <= va0 <= e["VAMAX"]):
                raise InitError("V_A0 outside [VAMIN, VAMAX]")
            x[ix["vm"]] = V0
            x[ix["ll1"]] = va0 / e["KA"]
            x[ix["ll2"]] = va0 / e["KA"]
            x[ix["va"]] = va0
            x[ix["xf"]] = Efd0
            self.Vref = V0 + va0 / e["KA"]
        # ---- PSS
        if self.pmodel == "STAB3":
            x[ix["pf"]] = self.P0e
            self.Pref = self.P0e
        elif self.pmodel == "IEEEST":
            x[ix["l1"]] = dw0
            x[ix["l2"]] = dw0
            x[ix["wo"]] = dw0
        # ---- governor
        g = self.g
        At, qNL, Dt = g["At"], g["qNL"], g["Dturb"]
        q0 = (Pm0 + At * qNL) / (At - Dt * dw0)
        geff0 = q0
        g0 = geff0
        if self.has_backlash:
            bl = ext["backlash"]
            g0 = geff0 + bl["b"] * bl["start"]  # start in [-1/2, 1/2]: where in the play
            x[ix["gy"]] = geff0
        if not (g["GMIN"] <= g0 <= g["GMAX"]):
            raise InitError("gate outside [GMIN, GMAX]")
        x[ix["e"]] = 0.0
        x[ix["c"]] = g0
        x[ix["g"]] = g0
        if self.pen_n:
            for k in range(self.pen_n):
                x[ix[f"q{k}"]] = q0
                x[ix[f"h{k}"]] = 1.0
        else:
            x[ix["q"]] = q0
        db = ext["govdb"]["db"] if "govdb" in ext else 0.0
        self.db = db
        self.nref = g["R"] * g0 + deadband(dw0, db)
        self.q0, self.geff0 = q0, geff0
        # ---- limiters outside the exciter
        if self.has_oel:
            I = self.XadIfd0 / ext["oel"]["ifd_rated"]
            if I > ext["oel"]["I_pu"]:
                raise InitError("OEL picked up at the start")
        if self.has_plantq:
            pq = ext["plant_q"]
            x[ix["pqf"]] = self._plantq_meas(P, Q, V, I)
            self.pq_set = x[ix["pqf"]]
        if self.has_vhz:
            if V0 / (1 + dw0) >= ext["vhz"]["pickup"]:
                raise InitError("V/Hz limiter active at the start")
        if self.has_scl:
            if abs(I) >= ext["scl"]["I_pu"]:
                raise InitError("stator current limiter picked up at the start")
        self.x0 = x
        return list(x)

    def _plantq_meas(self, P, Q, V, I):
        pq = self.ext["plant_q"]
        if pq["mode"] == "q":
            return Q
        return abs(V - 1j * pq["Xt"] * I)

    def _sexs_limits(self, Vt, XadIfd):
        e = self.e
        lo, hi = e["EMIN"], e["EMAX"]
        c = self.ext.get("ceiling")
        if c is not None and self.emodel == "SEXS":
            if c["mode"] == "constant":
                hi = c["EMAX"]
            else:
                hi = Vt * c["VRMAX"] - c["KC"] * XadIfd
        return lo, hi

    # ------------------------------------------------------------------ dynamics
    def set_grid(self, Em, thg, zfac, Re, Xe):
        """Grid mode: source magnitude Em(t), angle thg(t) (callables), impedance
        (Re + jXe)·zfac(t) (zfac a callable or None)."""
        self.mode = "grid"
        self.Em, self.thg, self.zfac = Em, thg, zfac
        self.Ze = complex(Re, Xe)

    def set_playback(self, vmag, vang):
        self.mode = "playback"
        self.vmag, self.vang = vmag, vang

    def terminal(self, t, delta, Eppq, Eppd):
        """(v_d, v_q, i_d, i_q) at time t."""
        m = self.m
        if self.mode == "playback":
            Vm = self.vmag(t)
            a = delta - self.vang(t)
            vd = Vm * math.sin(a)
            vq = Vm * math.cos(a)
            i_d, i_q = self._stator_playback(Eppq, Eppd, vd, vq)
            return vd, vq, i_d, i_q
        Em = self.Em(t)
        a = delta - self.thg(t)
        ed = Em * math.sin(a)
        eq = Em * math.cos(a)
        Ze = self.Ze
        if self.zfac is not None:
            Ze = Ze * self.zfac(t)
        A = 1.0 / (1.0 + Ze * self.yl)
        B = Ze * A
        aed = A.real * ed - A.imag * eq
        aeq = A.real * eq + A.imag * ed
        Br, Bi = B.real, B.imag
        Ra, Xd2, Xq2 = m["R_a"], m["Xppd"], m["Xppq"]
        a11, a12, b1 = Br + Ra, -(Bi + Xq2), Eppd - aed
        a21, a22, b2 = Bi + Xd2, Br + Ra, Eppq - aeq
        det = a11 * a22 - a12 * a21
        i_d = (b1 * a22 - a12 * b2) / det
        i_q = (a11 * b2 - a21 * b1) / det
        vd = aed + Br * i_d - Bi * i_q
        vq = aeq + Bi * i_d + Br * i_q
        return vd, vq, i_d, i_q

    def rhs(self, t, x):
        return self._eval(t, x, False)

    def outputs(self, t, x):
        return self._eval(t, x, True)

    def _eval(self, t, x, out):
        m, ix, ext = self.m, self.ix, self.ext
        delta, dw, Epq, psikd, Eppd = x[0], x[1], x[2], x[3], x[4]
        Eppq = self.K3d * Epq + self.K4d * psikd
        vd, vq, i_d, i_q = self.terminal(t, delta, Eppq, Eppd)
        Vt = math.hypot(vd, vq)
        P = vd * i_d + vq * i_q
        Q = vq * i_d - vd * i_q
        Xppd, Xppq, Xl, Xpd = m["Xppd"], m["Xppq"], m["Xl"], m["Xpd"]
        psid = Eppq - Xppd * i_d
        psiq = -Eppd - Xppq * i_q
        Te = psid * i_q - psiq * i_d
        kd = Epq - psikd - (Xpd - Xl) * i_d
        if self.mmodel == "GENSAE":
            Se = se_exp(math.hypot(Eppq, Eppd), m["S10"], m["S12"])
            XadIfd = Epq + self.K1d * kd + (m["Xd"] - Xpd) * i_d + Se * Eppq
            dEppd = (-Eppd + (m["Xq"] - Xppq) * i_q - self.gamma * Se * Eppd) / m["Tppq0"]
        else:
            Se = se_quad(Epq, self.qab)
            XadIfd = self.K1d * kd + (m["Xd"] - Xpd) * i_d + (1 + Se) * Epq
            dEppd = (-Eppd + (m["Xq"] - Xppq) * i_q) / m["Tppq0"]
        dx = [0.0] * self.n
        dx[3] = kd / m["Tppd0"]
        dx[4] = dEppd
        # -------- PSS
        VS = 0.0
        if self.pmodel == "STAB3":
            p = self.p
            pf = x[ix["pf"]]
            if p["Tt"] > 0:
                dx[ix["pf"]] = (P - pf) / p["Tt"]
            else:
                pf = P
            u1 = pf - self.Pref
            x2, x3 = x[ix["x2"]], x[ix["x3"]]
            dx[ix["x2"]] = (u1 - x2) / p["TX1"]
            dx[ix["x3"]] = (x2 - x3) / p["TX2"]
            lim = ext.get("pss_limit")
            vs = -(p["KX"] / p["TX2"]) * (x2 - x3)
            if lim is not None:
                VS = clamp(vs, lim["VS_min"], lim["VS_max"])
            else:
                VS = clamp(vs, -p["VLIM"], p["VLIM"])
        elif self.pmodel == "IEEEST":
            p = self.p
            u = dw
            l1, l2, wo = x[ix["l1"]], x[ix["l2"]], x[ix["wo"]]
            dx[ix["l1"]] = (u - l1) / p["T2"]
            y1 = (p["T1"] / p["T2"]) * u + (1 - p["T1"] / p["T2"]) * l1
            dx[ix["l2"]] = (y1 - l2) / p["T4"]
            y2 = (p["T3"] / p["T4"]) * y1 + (1 - p["T3"] / p["T4"]) * l2
            dx[ix["wo"]] = (y2 - wo) / p["T6"]
            y3 = (p["T5"] / p["T6"]) * (y2 - wo)
            VS = clamp(p["KS"] * y3, p["LSMIN"], p["LSMAX"])
        # -------- limiters acting on the AVR summing point
        Vsum = 0.0
        oel_on = False
        if self.has_oel:
            o = ext["oel"]
            I = XadIfd / o["ifd_rated"]
            A = x[ix["oelA"]]
            dx[ix["oelA"]] = (I * I - o["I_pu"] ** 2) if I > o["I_pu"] else 0.0
            v = x[ix["oelV"]]
            if A >= o["A_max"]:
                oel_on = True
                dx[ix["oelV"]] = nonwindup(v, o["Ki"] * (o["I_lim"] - I), o["Vmin"], 0.0)
            Vsum += clamp(v, o["Vmin"], 0.0)
        if self.has_plantq:
            pq = ext["plant_q"]
            It = complex(i_q, -i_d) * cmath.exp(1j * delta) if pq["mode"] == "poi_v" else 0.0
            if pq["mode"] == "q":
                meas = Q
            else:
                Vc = complex(vq, -vd) * cmath.exp(1j * delta)
                meas = abs(Vc - 1j * pq["Xt"] * It)
            f = x[ix["pqf"]]
            dx[ix["pqf"]] = (meas - f) / pq["Tm"]
            xq = x[ix["pqx"]]
            err = self.pq_set - f
            if pq["mode"] == "poi_v":
                err = err  # volts: raise the AVR set point when the HV voltage is low
            if abs(err) <= pq.get("db", 0.0):
                err = 0.0
            else:
                err -= math.copysign(pq.get("db", 0.0), err)
            dx[ix["pqx"]] = nonwindup(xq, pq["Ki"] * err, -pq["lim"], pq["lim"])
            Vsum += clamp(xq, -pq["lim"], pq["lim"])
        if self.has_vhz:
            vz = ext["vhz"]
            ratio = Vt / (1.0 + dw)
            xz = x[ix["vhzx"]]
            if ratio > vz["pickup"]:
                f = -vz["Ki"] * (ratio - vz["pickup"])
            else:
                f = -xz / vz["Treset"]
            dx[ix["vhzx"]] = nonwindup(xz, f, vz["Vmin"], 0.0)
            Vsum += clamp(xz, vz["Vmin"], 0.0)
        if self.has_scl:
            sc = ext["scl"]
            It = math.hypot(i_d, i_q)
            A = x[ix["sclA"]]
            dx[ix["sclA"]] = (It * It - sc["I_pu"] ** 2) if It > sc["I_pu"] else 0.0
            xs = x[ix["sclx"]]
            if A >= sc["A_max"] and Q > 0.0:
                dx[ix["sclx"]] = nonwindup(xs, sc["Ki"] * (sc["I_lim"] - It), sc["Vmin"], 0.0)
            Vsum += clamp(xs, sc["Vmin"], 0.0)
        # -------- exciter
        e = self.e
        Vref = self.Vref + self.offsets[0]
        if self.emodel == "SEXS":
            verr = Vref - Vt + VS + Vsum
            xLL = x[ix["xLL"]]
            dx[ix["xLL"]] = (verr - xLL) / e["TB"]
            yLL = e["TA_TB"] * verr + (1 - e["TA_TB"]) * xLL
            xE = x[ix["xE"]]
            lo, hi = self._sexs_limits(Vt, XadIfd)
            dx[ix["xE"]] = nonwindup(xE, (e["K"] * yLL - xE) / e["TE"], lo, hi)
            vr = clamp(xE, lo, hi)
            if self.rot:
                rx = ext["rotating_exciter"]
                efdx = x[ix["efdx"]]
                se = exc_sat_quad(efdx, rx["E1"], rx["SE1"], rx["E2"], rx["SE2"])
                dx[ix["efdx"]] = (vr - (self.rot_ke + se) * efdx) / rx["TE"]
                Efd = efdx
            else:
                Efd = vr
        else:
            vm = x[ix["vm"]]
            if e["TR"] > 0:
                dx[ix["vm"]] = (Vt - vm) / e["TR"]
            else:
                vm = Vt
            xf = x[ix["xf"]]
            va = x[ix["va"]]
            klr = e["KLR"] * max(0.0, XadIfd - e["ILR"])
            vx = va - klr
            vf = (e["KF"] / e["TF"]) * (vx - xf) if e["KF"] > 0 else 0.0
            dx[ix["xf"]] = (vx - xf) / e["TF"]
            vi = clamp(Vref - vm - vf + VS + Vsum, e["VIMIN"], e["VIMAX"])
            ll1 = x[ix["ll1"]]
            if e["TB"] > 0:
                dx[ix["ll1"]] = (vi - ll1) / e["TB"]
                v1 = (e["TC"] / e["TB"]) * vi + (1 - e["TC"] / e["TB"]) * ll1
            else:
                v1 = vi
            ll2 = x[ix["ll2"]]
            if e["TB1"] > 0:
                dx[ix["ll2"]] = (v1 - ll2) / e["TB1"]
                v2 = (e["TC1"] / e["TB1"]) * v1 + (1 - e["TC1"] / e["TB1"]) * ll2
            else:
                v2 = v1
            dx[ix["va"]] = nonwindup(va, (e["KA"] * v2 - va) / e["TA"], e["VAMIN"], e["VAMAX"])
            c = ext.get("ceiling")
            vrmax, kc = e["VRMAX"], e["KC"]
            if c is not None:
                vrmax, kc = c["VRMAX"], c["KC"]
            Efd = clamp(clamp(va, e["VAMIN"], e["VAMAX"]) - klr, Vt * e["VRMIN"], Vt * vrmax - kc * XadIfd)
        dx[2] = (Efd - XadIfd) / m["Tpd0"]
        # -------- governor (HYGOV)
        g = self.g
        dwg = dw
        e_ = x[ix["e"]]
        nref = self.nref + self.offsets[1]
        if self.agc is not None:
            nref += g["R"] * self.agc(t)
        de = (nref - deadband(dwg, self.db) - g["R"] * x[ix["c"]] - e_) / g["Tf"]
        dx[ix["e"]] = de
        v = e_ / (g["r"] * g["Tr"]) + de / g["r"]
        v = clamp(v, -g["VELM"], g["VELM"])
        cg = x[ix["c"]]
        dx[ix["c"]] = nonwindup(cg, v, g["GMIN"], g["GMAX"])
        gg = x[ix["g"]]
        dg = (clamp(cg, g["GMIN"], g["GMAX"]) - gg) / g["Tg"]
        dx[ix["g"]] = dg
        geff = gg
        if self.has_backlash:
            bl = ext["backlash"]
            gy = x[ix["gy"]]
            half = 0.5 * bl["b"]
            if gg - gy >= half and dg > 0.0:
                dgy = dg + (gg - half - gy) / 0.01
            elif gy - gg >= half and dg < 0.0:
                dgy = dg + (gg + half - gy) / 0.01
            else:
                dgy = 0.0
            dx[ix["gy"]] = dgy
            geff = gy
        if self.pen_n:
            N = self.pen_n
            pn = ext["penstock"]
            Tw, Tpe = g["Tw"], pn["Te"]
            Lsec = Tw / N
            Csec = Tpe * Tpe / (Tw * N)
            hN = x[ix[f"h{N - 1}"]]
            qT = geff * math.sqrt(max(hN, 0.0))
            hprev = 1.0
            for k in range(N):
                qk = x[ix[f"q{k}"]]
                hk = x[ix[f"h{k}"]]
                dx[ix[f"q{k}"]] = (hprev - hk) / Lsec
                qnext = x[ix[f"q{k + 1}"]] if k + 1 < N else qT
                dx[ix[f"h{k}"]] = (qk - qnext) / Csec
                hprev = hk
            h = hN
            qturb = qT
        else:
            q = x[ix["q"]]
            h = (q / geff) ** 2
            dx[ix["q"]] = (1.0 - h) / g["Tw"]
            qturb = q
        Pm = g["At"] * h * (qturb - g["qNL"]) - g["Dturb"] * geff * dwg
        # -------- mechanics
        H, D = m["H"], m["D"]
        if self.has_shaft:
            dwt, ths = x[ix["dwt"]], x[ix["ths"]]
            Tm = Pm / (1.0 + dwt)
            if self.torque_noise is not None:
                Tm += self.torque_noise(t)
            Ts = self.Ks * ths + self.Ds * (dwt - dw)
            dx[ix["dwt"]] = (Tm - Ts) / (2 * self.Ht)
            dx[ix["ths"]] = self.wb * (dwt - dw)
            dx[1] = (Ts - Te - D * dw) / (2 * self.Hg)
        else:
            dx[1] = ((Pm - D * dw) / (1.0 + dw) - Te) / (2 * H)
        dx[0] = self.wb * dw
        if not out:
            return dx
        return {
            "vd": vd, "vq": vq, "id": i_d, "iq": i_q, "Vt": Vt, "P": P, "Q": Q,
            "Efd": Efd, "XadIfd": XadIfd, "dw": dw, "Pm": Pm, "VS": VS, "delta": delta,
            "oel_on": oel_on, "Vsum": Vsum,
        }

    # ------------------------------------------------------------------ measurement
    def measured(self, o):
        """P, Q at the PMU (after the terminal load), system base, and the terminal phasor
        (v_r, v_i)."""
        d = o["delta"]
        cd, sd = math.cos(d), math.sin(d)
        vr = o["vq"] * cd + o["vd"] * sd
        vi = o["vq"] * sd - o["vd"] * cd
        V2 = o["Vt"] ** 2
        Pm = o["P"] - self.yl.real * V2
        Qm = o["Q"] + self.yl.imag * V2
        k = self.mva / self.sys_mva
        return vr, vi, Pm * k, Qm * k


def simulate(unit: TrueUnit, t_end: float, t_eval: np.ndarray, rtol=1e-8, atol=1e-10,
             x0=None, max_step=np.inf, t_start=0.0):
    """Integrates the unit from its initial state with scipy's LSODA (solve_ivp) and returns
    (states at t_eval, solver result)."""
    from scipy.integrate import solve_ivp

    y0 = unit.x0 if x0 is None else x0
    sol = solve_ivp(unit.rhs, (t_start, t_end), y0, method="LSODA", t_eval=t_eval, rtol=rtol,
                    atol=atol, max_step=max_step)
    if sol.status != 0:
        raise RuntimeError(f"integration failed: {sol.message}")
    return sol.y, sol
