//! The discretised bodies ("arms") of the finite-volume model and the implicit solve.
//!
//! An arm is a 1-D chain of cells numbered from its contact face (cell 0) to its far end (cell n − 1): the skin
//! from the surface inwards, the object from the contact face outwards. Per unit area, cell i has the capacity
//! `C_i = ρ c Δx`, conductance `g_i = 1/(Δx_i/2k_i + Δx_{i+1}/2k_{i+1})` to cell i + 1, a perfusion conductance
//! `p_i = s · ω ρ_b c_b Δx` to arterial blood (s the perfusion scale), metabolic heat `m_i = q_m Δx`, and the far
//! end has a conductance `g_end = 2k/Δx` to a held temperature (zero when insulated). The net heat into cell i is
//! `F_i(T) = g_{i−1}(T_{i−1} − T_i) + g_i(T_{i+1} − T_i) + p_i (T_art − T_i) + m_i [+ g_end (T_end − T_i)]
//! [+ g_side (T_partner − T_0)]`, where the contact side's partner is a fixed environment temperature or, in contact,
//! cell 0 of the other arm.
//!
//! The implicit systems `(κC + θh·(−∂F/∂T)) T = r` are symmetric, diagonally dominant and tridiagonal along the chain
//! skin-deep … skin-surface | object-face … object-far. They are solved by eliminating each arm from its far end
//! towards the contact (a Thomas sweep), solving the 2 × 2 system of the two contact cells (or the single surface
//! cell when not in contact), and substituting back outwards. The elimination depends only on the matrix, so it is
//! cached and reused while the step and the environment stay the same.

use super::TimeScheme;

/// One discretised body.
#[derive(Debug, Clone)]
pub(crate) struct Arm {
    /// Cell widths Δx \[m\], from the contact face.
    pub width_m: Vec<f64>,
    /// Cell centres \[m\] from the contact face.
    pub centre_m: Vec<f64>,
    /// Index of the layer each cell belongs to.
    pub layer: Vec<usize>,
    /// Conductivity of each cell [W/(m·K)].
    pub conductivity: Vec<f64>,
    /// Capacity ρ c Δx of each cell [J/(m²·K)].
    pub capacity: Vec<f64>,
    /// Conductance between cell i and i + 1 [W/(m²·K)]; one fewer than cells.
    pub link: Vec<f64>,
    /// Unscaled perfusion conductance ω ρ_b c_b Δx [W/(m²·K)].
    pub perfusion_base: Vec<f64>,
    /// Perfusion conductance in use (base times the perfusion scale) [W/(m²·K)].
    pub perfusion: Vec<f64>,
    /// Metabolic heat q_m Δx [W/m²].
    pub metabolic: Vec<f64>,
    /// Arterial temperature \[°C\].
    pub arterial_c: f64,
    /// Conductance from the last cell to the held far-end temperature [W/(m²·K)]; 0 when insulated.
    pub end_g: f64,
    /// Held far-end temperature \[°C\] (unused when insulated).
    pub end_c: f64,
    /// Constant heat into each cell [W/m²]: p_i T_art + m_i, plus g_end T_end in the last cell.
    pub source: Vec<f64>,
}

impl Arm {
    /// Number of cells.
    pub fn len(&self) -> usize {
        self.width_m.len()
    }

    /// Resistance of the half cell between the centre of cell 0 and the contact face [m²K/W].
    pub fn half_resistance(&self) -> f64 {
        0.5 * self.width_m[0] / self.conductivity[0]
    }

    /// Sets the perfusion scale and recomputes the constant sources.
    pub fn set_perfusion_scale(&mut self, scale: f64) {
        for i in 0..self.len() {
            self.perfusion[i] = scale * self.perfusion_base[i];
            self.source[i] = self.perfusion[i] * self.arterial_c + self.metabolic[i];
        }
        let last = self.len() - 1;
        self.source[last] += self.end_g * self.end_c;
    }

    /// Σ C_i T_i [J/m²].
    pub fn energy(&self, t: &[f64]) -> f64 {
        self.capacity.iter().zip(t).map(|(c, t)| c * t).sum()
    }

    /// Heat flows into the arm at state `t` [W/m²]; `side_in` is the flux in through the contact side.
    fn flows(&self, t: &[f64], side_in: f64) -> Flows {
        let perfusion = self
            .perfusion
            .iter()
            .zip(t)
            .map(|(p, t)| p * (self.arterial_c - t))
            .sum();
        let metabolic = self.metabolic.iter().sum();
        let end_in = self.end_g * (self.end_c - t[self.len() - 1]);
        Flows {
            perfusion,
            metabolic,
            end_in,
            side_in,
        }
    }
}

/// Heat flows into one arm [W/m² as rates, J/m² when integrated over a step].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Flows {
    /// Perfusion Σ p_i (T_art − T_i).
    pub perfusion: f64,
    /// Metabolic Σ m_i.
    pub metabolic: f64,
    /// In through the far end.
    pub end_in: f64,
    /// In through the contact side.
    pub side_in: f64,
}

impl Flows {
    fn add_scaled(&mut self, other: Flows, weight: f64) {
        self.perfusion += weight * other.perfusion;
        self.metabolic += weight * other.metabolic;
        self.end_in += weight * other.end_in;
        self.side_in += weight * other.side_in;
    }
}

/// What the skin's contact side (its surface) is connected to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Side {
    /// A fixed temperature through a conductance [W/(m²·K)] (air, plate, or nothing when g = 0).
    Fixed { g: f64, temp_c: f64 },
    /// Cell 0 of the object through a conductance [W/(m²·K)].
    Contact { g: f64 },
}

impl Side {
    fn g(&self) -> f64 {
        match *self {
            Side::Fixed { g, .. } | Side::Contact { g } => g,
        }
    }
}

/// TR-BDF2 stage fraction γ = 2 − √2; with it both stages have the same matrix C − d·h·∂F/∂T.
const GAMMA: f64 = 2.0 - std::f64::consts::SQRT_2;
/// d = γ/2 = (1 − γ)/(2 − γ).
const D: f64 = GAMMA / 2.0;
/// BDF2 stage: T₁ = A·T_γ − B·T₀ + d·h·F(T₁).
const A: f64 = 1.0 / (GAMMA * (2.0 - GAMMA));
const B: f64 = (1.0 - GAMMA) * (1.0 - GAMMA) / (GAMMA * (2.0 - GAMMA));
/// Weight w = √2/4 of the first two stages in TR-BDF2 written as a Runge–Kutta method (b = (w, w, d)).
const W: f64 = std::f64::consts::SQRT_2 / 4.0;
/// Hosea & Shampine (1996) embedded error estimate: `h·Σ (b − b̂)_i F_i` with the third-order companion
/// b̂ = ((1 − w)/3, (3w + 1)/3, d/3), so the coefficients of F(T₀), F(T_γ) and F(T₁) are these three (they sum to
/// zero, so constant sources cancel).
const E0: f64 = (4.0 * W - 1.0) / 3.0;
const E1: f64 = -1.0 / 3.0;
const E2: f64 = 2.0 * D / 3.0;

/// Pre-allocated buffers and the cached elimination.
#[derive(Debug, Clone)]
pub(crate) struct Work {
    inv_skin: Vec<f64>,
    inv_object: Vec<f64>,
    /// Elimination multipliers θh·g_i / pivot_{i+1} (one fewer than cells): one multiply-add per cell and sweep.
    mult_skin: Vec<f64>,
    mult_object: Vec<f64>,
    rhs_skin: Vec<f64>,
    rhs_object: Vec<f64>,
    stage_skin: Vec<f64>,
    stage_object: Vec<f64>,
    /// Pivots of the two contact cells (before inversion), for the 2 × 2 contact system.
    pivot0: (f64, f64),
    /// The matrix the cached elimination belongs to: κ, θh, side conductance, contact flag (as bits).
    key: Option<[u64; 4]>,
    /// Number of eliminations made (cache misses), for diagnostics.
    pub eliminations: usize,
    /// The next state, swapped with the model's state after a step.
    pub next_skin: Vec<f64>,
    pub next_object: Vec<f64>,
    /// Net heat into every cell at the start and at the end of the last step with an error estimate [W/m²] (for
    /// the Hermite dense output of adaptive stepping).
    pub flux_start_skin: Vec<f64>,
    pub flux_start_object: Vec<f64>,
    pub flux_end_skin: Vec<f64>,
    pub flux_end_object: Vec<f64>,
    /// The filtered local error estimate of the last such step \[K\].
    err_skin: Vec<f64>,
    err_object: Vec<f64>,
}

impl Work {
    pub fn new(skin_cells: usize, object_cells: usize) -> Self {
        let s = || vec![0.0; skin_cells];
        let o = || vec![0.0; object_cells];
        Work {
            inv_skin: s(),
            inv_object: o(),
            mult_skin: s(),
            mult_object: o(),
            rhs_skin: s(),
            rhs_object: o(),
            stage_skin: s(),
            stage_object: o(),
            pivot0: (0.0, 0.0),
            key: None,
            eliminations: 0,
            next_skin: s(),
            next_object: o(),
            flux_start_skin: s(),
            flux_start_object: o(),
            flux_end_skin: s(),
            flux_end_object: o(),
            err_skin: s(),
            err_object: o(),
        }
    }

    /// Forgets the cached elimination (after a change of coefficients).
    pub fn invalidate(&mut self) {
        self.key = None;
    }
}

/// The skin and, in contact, the object, with what the skin surface is connected to. Build with [`Bodies::new`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bodies<'a> {
    skin: &'a Arm,
    object: Option<&'a Arm>,
    side: Side,
}

/// Integrated heat over one step [J/m²]: into the skin and into the object.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct StepFlows {
    pub skin: Flows,
    pub object: Flows,
}

impl StepFlows {
    /// self += weight · other, field by field.
    pub fn add_scaled(&mut self, other: StepFlows, weight: f64) {
        self.skin.add_scaled(other.skin, weight);
        self.object.add_scaled(other.object, weight);
    }
}

impl<'a> Bodies<'a> {
    /// The bodies with the skin surface connected to `side`; contact without an object leaves the surface insulated.
    pub fn new(skin: &'a Arm, object: Option<&'a Arm>, side: Side) -> Self {
        let side = match (side, object) {
            (Side::Contact { .. }, None) => Side::Fixed { g: 0.0, temp_c: 0.0 },
            _ => side,
        };
        Bodies { skin, object, side }
    }

    /// The object when it takes part (in contact).
    fn coupled(&self) -> Option<(&Arm, f64)> {
        match self.side {
            Side::Contact { g } => self.object.map(|o| (o, g)),
            Side::Fixed { .. } => None,
        }
    }

    /// Flux into the skin through its surface and into the object through its face at a state [W/m²].
    fn side_fluxes(&self, skin: &[f64], object: &[f64]) -> (f64, f64) {
        match self.side {
            Side::Contact { g } => {
                let q = g * (object[0] - skin[0]);
                (q, -q)
            }
            Side::Fixed { g, temp_c } => (g * (temp_c - skin[0]), 0.0),
        }
    }

    /// Heat flow rates into both arms at a state [W/m²].
    fn flows(&self, skin: &[f64], object: &[f64]) -> StepFlows {
        let (skin_in, object_in) = self.side_fluxes(skin, object);
        let skin_flows = self.skin.flows(skin, skin_in);
        let object_flows = self
            .coupled()
            .map_or(Flows::default(), |(o, _)| o.flows(object, object_in));
        StepFlows {
            skin: skin_flows,
            object: object_flows,
        }
    }

    /// Heat into the skin's cell 0 from a fixed surface temperature that belongs to the constant sources.
    fn side_source(&self) -> f64 {
        match self.side {
            Side::Fixed { g, temp_c } => g * temp_c,
            Side::Contact { .. } => 0.0,
        }
    }

    /// Advances (`skin`, `object`) by one step of `h` \[s\] into (`to_skin`, `to_object`); returns the heat that
    /// entered each arm over the step [J/m²], consistent with the scheme so that Δ Σ C T equals it to rounding.
    /// The object arrays are only read and written in contact.
    pub fn advance(
        &self,
        scheme: TimeScheme,
        h: f64,
        (skin, object): (&[f64], &[f64]),
        (to_skin, to_object): (&mut [f64], &mut [f64]),
        work: &mut Work,
    ) -> StepFlows {
        match scheme {
            TimeScheme::BackwardEuler => {
                self.factor(1.0, h, work);
                self.set_rhs(work, skin, object, 1.0);
                self.add_sources(work, h);
                self.solve(work, h, to_skin, to_object);
                let mut flows = StepFlows::default();
                flows.add_scaled(self.flows(to_skin, to_object), h);
                flows
            }
            TimeScheme::TrBdf2 => self.advance_tr_bdf2(h, (skin, object), (to_skin, to_object), work),
        }
    }

    /// TR-BDF2: trapezoidal stage to t + γh, then BDF2 to t + h; both with the matrix C − d h ∂F/∂T.
    fn advance_tr_bdf2(
        &self,
        h: f64,
        (skin, object): (&[f64], &[f64]),
        (to_skin, to_object): (&mut [f64], &mut [f64]),
        work: &mut Work,
    ) -> StepFlows {
        let dh = D * h;
        self.factor(1.0, dh, work);
        // (C − dh J) T_γ = C T₀ + dh F(T₀) + dh S
        self.set_rhs(work, skin, object, 1.0);
        self.add_net_flux(work, skin, object, dh);
        self.add_sources(work, dh);
        let mut stage_skin = std::mem::take(&mut work.stage_skin);
        let mut stage_object = std::mem::take(&mut work.stage_object);
        self.solve(work, dh, &mut stage_skin, &mut stage_object);
        // (C − dh J) T₁ = C (A T_γ − B T₀) + dh S
        self.set_rhs(work, &stage_skin, &stage_object, A);
        self.sub_capacity(work, skin, object, B);
        self.add_sources(work, dh);
        self.solve(work, dh, to_skin, to_object);
        let mut flows = StepFlows::default();
        flows.add_scaled(self.flows(skin, object), A * dh);
        flows.add_scaled(self.flows(&stage_skin, &stage_object), A * dh);
        flows.add_scaled(self.flows(to_skin, to_object), dh);
        work.stage_skin = stage_skin;
        work.stage_object = stage_object;
        flows
    }

    /// The Hosea–Shampine local error estimate of the TR-BDF2 step of `h` \[s\] just made by [`Self::advance`] from
    /// (`skin`, `object`) to (`new_skin`, `new_object`) (its stage still in `work`): `(C − d h J)⁻¹ · h·(E0·F(T₀) +
    /// E1·F(T_γ) + E2·F(T₁))`, filtered by the step's own matrix so that it stays bounded for stiff components
    /// (Shampine's filter). Returns the largest magnitude over all cells \[K\]; also leaves F(T₀) and F(T₁) in
    /// `work.flux_start_*` and `work.flux_end_*` for dense output. Uses the cached elimination of the step.
    pub fn tr_bdf2_error(
        &self,
        h: f64,
        (skin, object): (&[f64], &[f64]),
        (new_skin, new_object): (&[f64], &[f64]),
        work: &mut Work,
    ) -> f64 {
        let dh = D * h;
        self.factor(1.0, dh, work);
        let (mut fs0, mut fo0) = (
            std::mem::take(&mut work.flux_start_skin),
            std::mem::take(&mut work.flux_start_object),
        );
        let (mut fs1, mut fo1) = (
            std::mem::take(&mut work.flux_end_skin),
            std::mem::take(&mut work.flux_end_object),
        );
        self.net_flux(skin, object, &mut fs0, &mut fo0);
        self.net_flux(new_skin, new_object, &mut fs1, &mut fo1);
        let coupled = self.coupled().is_some();
        for ((r, a), b) in work.rhs_skin.iter_mut().zip(&fs0).zip(&fs1) {
            *r = h * (E0 * a + E2 * b);
        }
        if coupled {
            for ((r, a), b) in work.rhs_object.iter_mut().zip(&fo0).zip(&fo1) {
                *r = h * (E0 * a + E2 * b);
            }
        }
        let (stage_skin, stage_object) = (
            std::mem::take(&mut work.stage_skin),
            std::mem::take(&mut work.stage_object),
        );
        self.add_net_flux(work, &stage_skin, &stage_object, h * E1);
        let (mut err_skin, mut err_object) = (std::mem::take(&mut work.err_skin), std::mem::take(&mut work.err_object));
        self.solve(work, dh, &mut err_skin, &mut err_object);
        let largest = |v: &[f64]| v.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        let mut error = largest(&err_skin);
        if coupled {
            error = error.max(largest(&err_object));
        }
        (work.stage_skin, work.stage_object) = (stage_skin, stage_object);
        (work.err_skin, work.err_object) = (err_skin, err_object);
        (work.flux_start_skin, work.flux_start_object) = (fs0, fo0);
        (work.flux_end_skin, work.flux_end_object) = (fs1, fo1);
        error
    }

    /// Net heat into every cell at a state, F(T) [W/m²], into (`out_skin`, `out_object`) (the object only in contact).
    fn net_flux(&self, skin: &[f64], object: &[f64], out_skin: &mut [f64], out_object: &mut [f64]) {
        let (skin_in, object_in) = self.side_fluxes(skin, object);
        out_skin.iter_mut().for_each(|f| *f = 0.0);
        add_flux(self.skin, skin, skin_in, 1.0, out_skin);
        if let Some((o, _)) = self.coupled() {
            out_object.iter_mut().for_each(|f| *f = 0.0);
            add_flux(o, object, object_in, 1.0, out_object);
        }
    }

    /// Solves the steady state F(T) = 0 into (`to_skin`, `to_object`). The caller guarantees that the system is
    /// grounded (some conductance to a held temperature or perfusion), otherwise the result is not finite.
    pub fn steady(&self, (to_skin, to_object): (&mut [f64], &mut [f64]), work: &mut Work) {
        self.factor(0.0, 1.0, work);
        work.rhs_skin.iter_mut().for_each(|r| *r = 0.0);
        work.rhs_object.iter_mut().for_each(|r| *r = 0.0);
        self.add_sources(work, 1.0);
        self.solve(work, 1.0, to_skin, to_object);
    }

    /// rhs = coef · C T.
    fn set_rhs(&self, work: &mut Work, skin: &[f64], object: &[f64], coef: f64) {
        set_capacity(self.skin, skin, coef, &mut work.rhs_skin);
        if let Some((o, _)) = self.coupled() {
            set_capacity(o, object, coef, &mut work.rhs_object);
        }
    }

    /// rhs −= coef · C T.
    fn sub_capacity(&self, work: &mut Work, skin: &[f64], object: &[f64], coef: f64) {
        set_capacity_sub(self.skin, skin, coef, &mut work.rhs_skin);
        if let Some((o, _)) = self.coupled() {
            set_capacity_sub(o, object, coef, &mut work.rhs_object);
        }
    }

    /// rhs += coef · S (the constant sources, including a fixed surface temperature).
    fn add_sources(&self, work: &mut Work, coef: f64) {
        for (r, s) in work.rhs_skin.iter_mut().zip(&self.skin.source) {
            *r += coef * s;
        }
        work.rhs_skin[0] += coef * self.side_source();
        if let Some((o, _)) = self.coupled() {
            for (r, s) in work.rhs_object.iter_mut().zip(&o.source) {
                *r += coef * s;
            }
        }
    }

    /// rhs += coef · F(T) (net heat into every cell at state T).
    fn add_net_flux(&self, work: &mut Work, skin: &[f64], object: &[f64], coef: f64) {
        let (skin_in, object_in) = self.side_fluxes(skin, object);
        add_flux(self.skin, skin, skin_in, coef, &mut work.rhs_skin);
        if let Some((o, _)) = self.coupled() {
            add_flux(o, object, object_in, coef, &mut work.rhs_object);
        }
    }

    /// Eliminates the matrix κC + θh(−J) unless the cached elimination is for the same matrix.
    fn factor(&self, kappa: f64, theta_h: f64, work: &mut Work) {
        let contact = self.coupled().is_some();
        let key = [
            kappa.to_bits(),
            theta_h.to_bits(),
            self.side.g().to_bits(),
            u64::from(contact),
        ];
        if work.key == Some(key) {
            return;
        }
        let skin_pivot = eliminate(
            self.skin,
            kappa,
            theta_h,
            self.side.g(),
            (&mut work.inv_skin, &mut work.mult_skin),
        );
        let object_pivot = match self.coupled() {
            Some((o, g)) => eliminate(o, kappa, theta_h, g, (&mut work.inv_object, &mut work.mult_object)),
            None => 0.0,
        };
        work.pivot0 = (skin_pivot, object_pivot);
        work.key = Some(key);
        work.eliminations += 1;
    }

    /// Solves with the eliminated matrix; overwrites the rhs buffers.
    fn solve(&self, work: &mut Work, theta_h: f64, to_skin: &mut [f64], to_object: &mut [f64]) {
        forward(&work.mult_skin, &mut work.rhs_skin);
        let skin0 = match self.coupled() {
            Some((_, g)) => {
                forward(&work.mult_object, &mut work.rhs_object);
                let (ps, po) = work.pivot0;
                let c = theta_h * g;
                let (rs, ro) = (work.rhs_skin[0], work.rhs_object[0]);
                let det = ps * po - c * c;
                let object0 = (ro * ps + c * rs) / det;
                backward(
                    (&work.inv_object, &work.mult_object),
                    &work.rhs_object,
                    object0,
                    to_object,
                );
                (rs * po + c * ro) / det
            }
            None => work.rhs_skin[0] * work.inv_skin[0],
        };
        backward((&work.inv_skin, &work.mult_skin), &work.rhs_skin, skin0, to_skin);
    }
}

/// Thomas elimination from the far end towards cell 0 of the matrix with diagonal
/// κC_i + θh(g_{i−1} + g_i + p_i [+ g_end] [+ g_side]) and off-diagonal −θh g_i. Stores inverse pivots and the
/// multipliers θh·g_i/pivot_{i+1}; returns the pivot of cell 0.
fn eliminate(arm: &Arm, kappa: f64, theta_h: f64, side_g: f64, (inv_pivot, mult): (&mut [f64], &mut [f64])) -> f64 {
    let n = arm.len();
    let mut pivot = 0.0;
    for i in (0..n).rev() {
        let inward = if i + 1 < n { arm.link[i] } else { arm.end_g };
        let outward = if i > 0 { arm.link[i - 1] } else { side_g };
        let diag = kappa * arm.capacity[i] + theta_h * (inward + outward + arm.perfusion[i]);
        pivot = if i + 1 < n {
            let c = theta_h * arm.link[i];
            mult[i] = c * inv_pivot[i + 1];
            diag - c * mult[i]
        } else {
            diag
        };
        inv_pivot[i] = 1.0 / pivot;
    }
    pivot
}

/// Forward sweep of the right-hand side (far end → cell 0), in place: one multiply-add per cell.
fn forward(mult: &[f64], rhs: &mut [f64]) {
    for i in (0..rhs.len() - 1).rev() {
        rhs[i] += mult[i] * rhs[i + 1];
    }
}

/// Back substitution (cell 0 → far end) given the value of cell 0: T_{i+1} = r_{i+1}/pivot_{i+1} + m_i·T_i.
fn backward((inv_pivot, mult): (&[f64], &[f64]), rhs: &[f64], first: f64, out: &mut [f64]) {
    out[0] = first;
    for i in 0..out.len() - 1 {
        out[i + 1] = rhs[i + 1] * inv_pivot[i + 1] + mult[i] * out[i];
    }
}

fn set_capacity(arm: &Arm, t: &[f64], coef: f64, rhs: &mut [f64]) {
    for ((r, c), t) in rhs.iter_mut().zip(&arm.capacity).zip(t) {
        *r = coef * c * t;
    }
}

fn set_capacity_sub(arm: &Arm, t: &[f64], coef: f64, rhs: &mut [f64]) {
    for ((r, c), t) in rhs.iter_mut().zip(&arm.capacity).zip(t) {
        *r -= coef * c * t;
    }
}

/// rhs_i += coef · F_i(t), with `side_in` the flux into cell 0 through the contact side.
fn add_flux(arm: &Arm, t: &[f64], side_in: f64, coef: f64, rhs: &mut [f64]) {
    let n = arm.len();
    for i in 0..n {
        let mut f = arm.source[i] - arm.perfusion[i] * t[i];
        if i > 0 {
            f += arm.link[i - 1] * (t[i - 1] - t[i]);
        }
        if i + 1 < n {
            f += arm.link[i] * (t[i + 1] - t[i]);
        }
        rhs[i] += coef * f;
    }
    rhs[n - 1] -= coef * arm.end_g * t[n - 1];
    rhs[0] += coef * side_in;
}
