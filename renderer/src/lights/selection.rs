//! Which light next-event estimation samples from a point. Lights are chosen by power (docs/method.md
//! §2.2), with the infinite lights' share capped ([`nee_light_weights`]). Where a scene has
//! several finite lights, their share is redistributed at each point by how much each can light
//! it ([`EmitterBounds::importance`], pbrt-v4's exhaustive light sampler); likewise the
//! infinite lights' share when a directional light is among them (a sun's irradiance follows
//! the surface's orientation, a sky's does not). Within each kind the importance is mixed with
//! the power proportions, so every light with power keeps a probability of at least
//! [`POWER_SHARE`] times its power share — up to [`MAX_SPATIAL_LIGHTS`] finite lights weighed
//! one by one; more are chosen through a tree of their bounds ([`EmitterTree`], the mixture at
//! every level). Any selection that gives every contributing light a non-zero probability has
//! the same expected image; this one puts the samples where the light comes from.
//!
//! Why: by power alone, a light that radiates mostly into nothing (a far, bright sun-like
//! sphere; a point light next to a projector; a sky, whose power is its flux through the whole
//! scene) takes most of the samples everywhere, and the lights that actually light a point are
//! drawn rarely, with large weights (speckles).

use super::bounds::{EmitterBounds, LightBounds, LightBounds4};
use super::emitter_tree::{EmitterTree, TreeEmitter, MAX_EMITTERS};
use crate::sampling::{Distribution1D, ONE_MINUS_EPSILON};
use glam::Vec3;

/// Most lights of one kind (finite or infinite) the selection weighs one by one (every light
/// sample and every MIS density evaluates each one's importance). More finite lights, up to
/// [`MAX_EMITTERS`], are chosen through a tree ([`EmitterTree`]); beyond that, and for more
/// infinite lights, that kind is selected by power.
pub const MAX_SPATIAL_LIGHTS: usize = 64;

/// The share of a kind's probability that stays proportional to power at every point (a
/// defensive mixture): the importance is an estimate of how much a light delivers, blind to
/// occlusion and to the BSDF, and a light it underrates must not be sampled with a huge weight.
pub const POWER_SHARE: f32 = 0.1;

/// The light-selection distribution for next-event estimation.
#[derive(Debug, Clone)]
pub struct LightSelection {
    /// By power, the infinite lights capped: the whole selection without `split`.
    by_power: Distribution1D,
    /// The point-dependent selection, when finite or infinite lights are weighed per point.
    split: Option<Box<Split>>,
}

/// Where a light sits in the split selection.
#[derive(Debug, Clone, Copy)]
enum Slot {
    /// Index among the finite lights.
    Finite(u32),
    /// Index among the infinite lights.
    Infinite(u32),
}

/// The lights of one kind, chosen among themselves.
#[derive(Debug, Clone)]
struct Group {
    /// Light index of each member.
    lights: Vec<u32>,
    /// Selection among the members by their weights by power.
    by_power: Distribution1D,
    /// The members' emission bounds, when the group is weighed per point.
    bounds: Option<Weighing>,
}

/// What a group weighs its members by.
#[derive(Debug, Clone)]
enum Weighing {
    /// Finite lights, four to a pack (4-wide lanes).
    Finite(Vec<LightBounds4>),
    /// Infinite lights, one by one (a sun and a sky or two).
    Infinite(Vec<EmitterBounds>),
    /// More finite lights than a group weighs one by one: a tree of their bounds.
    Tree(Box<EmitterTree>),
}

/// A fixed share for each kind of light, and within each kind a choice that may depend on the
/// point.
#[derive(Debug, Clone)]
struct Split {
    /// The finite lights.
    finite: Group,
    /// The infinite lights.
    infinite: Group,
    /// Where each light sits.
    slot: Vec<Slot>,
    /// Probability of choosing a finite light (1 without infinite lights).
    finite_pmf: f32,
}

/// The largest importance counted (the sum of [`MAX_SPATIAL_LIGHTS`] of them stays finite).
pub(super) const IMPORTANCE_CAP: f32 = 1e30;

impl LightSelection {
    /// Builds the selection from each light's power (channel mean) and emission bounds.
    pub fn new(powers: &[f32], bounds: &[EmitterBounds]) -> Self {
        debug_assert_eq!(powers.len(), bounds.len());
        let infinite: Vec<bool> = bounds.iter().map(EmitterBounds::is_infinite).collect();
        let by_power = Distribution1D::new(&nee_light_weights(powers, &infinite));
        let members = |inf: bool| -> Vec<u32> {
            (0..bounds.len() as u32)
                .filter(|&i| infinite[i as usize] == inf)
                .collect()
        };
        let (finite, infinite) = (members(false), members(true));
        // Finite lights differ in position and direction; infinite ones only matter to each
        // other when a directional light is among them (environments relate by power).
        let weigh_finite = (2..=MAX_EMITTERS).contains(&finite.len());
        let weigh_infinite = (2..=MAX_SPATIAL_LIGHTS).contains(&infinite.len())
            && infinite
                .iter()
                .any(|&i| matches!(bounds[i as usize], EmitterBounds::Directional { .. }));
        if !weigh_finite && !weigh_infinite {
            return LightSelection {
                by_power,
                split: None,
            };
        }
        // A group's bounds are packed only when it is weighed per point (an unweighed group of
        // more lights than a tree takes selects by power).
        let weighing = |lights: &[u32], weights: &[f32]| {
            let members: Vec<EmitterBounds> = lights.iter().map(|&i| bounds[i as usize]).collect();
            let finite: Vec<LightBounds> = members
                .iter()
                .filter_map(|b| match b {
                    EmitterBounds::Finite(f) => Some(*f),
                    _ => None,
                })
                .collect();
            if finite.len() != members.len() {
                Weighing::Infinite(members)
            } else if finite.len() > MAX_SPATIAL_LIGHTS {
                let emitters: Vec<TreeEmitter> = finite
                    .iter()
                    .zip(weights)
                    .map(|(&bounds, &weight)| TreeEmitter {
                        bounds,
                        weight,
                        key: bounds.center(),
                    })
                    .collect();
                match EmitterTree::new(&emitters) {
                    Some(tree) => Weighing::Tree(Box::new(tree)),
                    None => unreachable!("{} lights are within a tree's range", finite.len()),
                }
            } else {
                Weighing::Finite(finite.chunks(4).map(LightBounds4::new).collect())
            }
        };
        let group = |lights: Vec<u32>, weigh: bool| {
            let weights: Vec<f32> = lights.iter().map(|&i| by_power.pmf(i as usize)).collect();
            Group {
                by_power: Distribution1D::new(&weights),
                bounds: weigh.then(|| weighing(&lights, &weights)),
                lights,
            }
        };
        let mut slot = vec![Slot::Finite(0); bounds.len()];
        for (k, &i) in finite.iter().enumerate() {
            slot[i as usize] = Slot::Finite(k as u32);
        }
        for (k, &i) in infinite.iter().enumerate() {
            slot[i as usize] = Slot::Infinite(k as u32);
        }
        let finite_pmf: f64 = finite
            .iter()
            .map(|&i| by_power.pmf(i as usize) as f64)
            .sum();
        let finite_pmf = if infinite.is_empty() {
            1.0
        } else {
            finite_pmf.min(1.0) as f32
        };
        let split = Split {
            finite: group(finite, weigh_finite),
            infinite: group(infinite, weigh_infinite),
            slot,
            finite_pmf,
        };
        LightSelection {
            by_power,
            split: Some(Box::new(split)),
        }
    }

    /// The selection by power alone (infinite lights capped).
    pub fn by_power(&self) -> &Distribution1D {
        &self.by_power
    }

    /// Whether the selection depends on the point.
    pub fn is_spatial(&self) -> bool {
        self.split.is_some()
    }

    /// Picks a light for a point `p` with unit normal `n` (`Vec3::ZERO`: none) with `u` in
    /// [0, 1); returns (light index, probability, `u` rescaled to [0, 1) within the choice).
    #[inline]
    pub fn sample(&self, p: Vec3, n: Vec3, u: f32) -> (usize, f32, f32) {
        let Some(s) = &self.split else {
            return self.by_power.sample(u);
        };
        let (group, share, u) = if s.infinite.lights.is_empty() || u < s.finite_pmf {
            (
                &s.finite,
                s.finite_pmf,
                (u / s.finite_pmf).min(ONE_MINUS_EPSILON),
            )
        } else {
            let rest = 1.0 - s.finite_pmf;
            (
                &s.infinite,
                rest,
                ((u - s.finite_pmf) / rest).clamp(0.0, ONE_MINUS_EPSILON),
            )
        };
        let (k, pmf, u_rest) = group.sample(p, n, u);
        (group.lights[k] as usize, share * pmf, u_rest)
    }

    /// The probability that [`Self::sample`] picks light `i` at `p` with normal `n`.
    #[inline]
    pub fn pmf(&self, p: Vec3, n: Vec3, i: u32) -> f32 {
        let Some(s) = &self.split else {
            return self.by_power.pmf(i as usize);
        };
        match s.slot[i as usize] {
            Slot::Finite(k) => s.finite_pmf * s.finite.pmf(p, n, k as usize),
            Slot::Infinite(k) => (1.0 - s.finite_pmf) * s.infinite.pmf(p, n, k as usize),
        }
    }
}

impl Group {
    /// Each member's selection weight at (`p`, `n`) into `w`: its importance's share scaled to
    /// 1 − [`POWER_SHARE`], plus its power share scaled to [`POWER_SHARE`]; returns their sum.
    #[inline]
    fn weights(
        &self,
        weighing: &Weighing,
        p: Vec3,
        n: Vec3,
        w: &mut [f32; MAX_SPATIAL_LIGHTS],
    ) -> f32 {
        let k = self.lights.len();
        match weighing {
            Weighing::Finite(packs) => {
                for (lanes, pack) in w.chunks_exact_mut(4).zip(packs) {
                    lanes.copy_from_slice(&pack.importance(p, n).to_array());
                }
            }
            Weighing::Infinite(bounds) => {
                for (w, b) in w.iter_mut().zip(bounds) {
                    *w = b.importance(p, n);
                }
            }
            // Not reached (a tree samples itself); nothing weighs, so the group would fall
            // back to power.
            Weighing::Tree(_) => w.fill(0.0),
        }
        let mut importance_sum = 0.0f32;
        for w in &mut w[..k] {
            // NaN (a degenerate point) counts as nothing; an overflow (a point on top of a
            // point light) as very much, without overflowing the sum.
            *w = if *w > 0.0 { w.min(IMPORTANCE_CAP) } else { 0.0 };
            importance_sum += *w;
        }
        let mut total = 0.0f32;
        if importance_sum > 0.0 && importance_sum.is_finite() {
            let scale = (1.0 - POWER_SHARE) / importance_sum;
            for (j, w) in w[..k].iter_mut().enumerate() {
                *w = *w * scale + POWER_SHARE * self.by_power.pmf(j);
                total += *w;
            }
        } else {
            // No member can reach the point by its bounds (or one overflows): by power.
            for (j, w) in w[..k].iter_mut().enumerate() {
                *w = self.by_power.pmf(j);
                total += *w;
            }
        }
        total
    }

    /// Picks a member: (index in the group, probability within it, `u` rescaled).
    #[inline]
    fn sample(&self, p: Vec3, n: Vec3, u: f32) -> (usize, f32, f32) {
        let weighing = match &self.bounds {
            None => return self.by_power.sample(u),
            Some(Weighing::Tree(tree)) => {
                return match tree.sample(p, n, u) {
                    Some((k, pmf, u_rest)) => (k as usize, pmf, u_rest),
                    None => (0, 0.0, 0.0),
                };
            }
            Some(w) => w,
        };
        let mut w = [0.0f32; MAX_SPATIAL_LIGHTS];
        let total = self.weights(weighing, p, n, &mut w);
        let target = u * total;
        let Some((j, below)) = pick(&w[..self.lights.len()], target) else {
            return (0, 0.0, 0.0);
        };
        let wj = w[j];
        let u_rest = ((target - below) / wj).clamp(0.0, ONE_MINUS_EPSILON);
        (j, wj / total, u_rest)
    }

    /// The probability that [`Self::sample`] picks member `k`.
    #[inline]
    fn pmf(&self, p: Vec3, n: Vec3, k: usize) -> f32 {
        let weighing = match &self.bounds {
            None => return self.by_power.pmf(k),
            Some(Weighing::Tree(tree)) => return tree.pmf(p, n, k as u32),
            Some(w) => w,
        };
        let mut w = [0.0f32; MAX_SPATIAL_LIGHTS];
        let total = self.weights(weighing, p, n, &mut w);
        w[k] / total
    }
}

/// The first of `weights` whose cumulative sum passes `target`, with the sum of the weights
/// before it; rounding can leave `target` past the last positive weight, which then takes it.
/// `None` when no weight is positive.
#[inline]
pub(super) fn pick(weights: &[f32], target: f32) -> Option<(usize, f32)> {
    let mut below = 0.0f32;
    let mut chosen = None;
    for (j, &wj) in weights.iter().enumerate() {
        if wj > 0.0 {
            chosen = Some((j, below));
            if target < below + wj {
                break;
            }
            below += wj;
        }
    }
    chosen
}

/// Selection weights of the lights for next-event estimation: proportional to power, as photons
/// are emitted, except that the infinite lights (directional, constant, environment map)
/// together get at most the share n∞/(n∞ + 1) when finite lights (area, point, spot) are
/// present too — ½ for one sky — each kind split by power within it (the cap is pbrt-v4's
/// fixed share for infinite lights).
///
/// Why: the power of an infinite light is its flux through the scene's whole bounding disk,
/// most of which reaches no surface a camera sees. Against it a spot or a small area light has
/// little power however much it lights, and was drawn for NEE rarely, with a large weight: on
/// a floor lit by a spot under a dim constant sky the path tracer had 50–80× the per-pixel
/// variance of Mitsuba 3's (which draws emitters uniformly). Below the cap nothing changes, so
/// scenes whose sky is weak by power render exactly as before. Any selection with a non-zero
/// probability for every light gives the same expected image.
pub fn nee_light_weights(powers: &[f32], infinite: &[bool]) -> Vec<f32> {
    let clean = |p: f32| {
        if p.is_finite() && p > 0.0 {
            p as f64
        } else {
            0.0
        }
    };
    let total = |inf: bool| -> f64 {
        powers
            .iter()
            .zip(infinite)
            .filter(|(_, &i)| i == inf)
            .map(|(&p, _)| clean(p))
            .sum()
    };
    let (finite_total, infinite_total) = (total(false), total(true));
    let n_infinite = infinite.iter().filter(|&&i| i).count() as f64;
    let cap = n_infinite / (n_infinite + 1.0);
    if finite_total <= 0.0 || infinite_total <= cap / (1.0 - cap) * finite_total {
        // One kind only, or the infinite lights' power share is within the cap: by power.
        return powers.to_vec();
    }
    powers
        .iter()
        .zip(infinite)
        .map(|(&p, &inf)| {
            let share = if inf {
                cap / infinite_total
            } else {
                (1.0 - cap) / finite_total
            };
            (clean(p) * share) as f32
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lights::bounds::LightBounds;
    use crate::sampling::{rng_for, UniformSource};

    /// Three finite lights — a point light, a downward-facing disk-like emitter and a narrow
    /// beam — and optionally a sky.
    fn lights(with_sky: bool) -> (Vec<f32>, Vec<EmitterBounds>) {
        let mut powers = vec![40.0, 5.0, 2.0];
        let mut bounds = vec![
            EmitterBounds::Finite(LightBounds::omnidirectional(
                Vec3::new(10.0, 10.0, 0.0),
                0.0,
                40.0 / (4.0 * std::f32::consts::PI),
            )),
            EmitterBounds::Finite(LightBounds::cone(
                Vec3::new(0.0, 2.0, 0.0),
                0.5,
                5.0 / std::f32::consts::PI,
                -Vec3::Y,
                1.0,
                0.0,
            )),
            EmitterBounds::Finite(LightBounds::cone(
                Vec3::new(-2.0, 2.0, 0.0),
                0.0,
                2.0 / 0.1,
                Vec3::new(0.0, -1.0, 0.0),
                0.98,
                1.0,
            )),
        ];
        if with_sky {
            powers.push(500.0);
            bounds.push(EmitterBounds::Environment { irradiance: 3.0 });
        }
        (powers, bounds)
    }

    fn points() -> Vec<(Vec3, Vec3)> {
        let mut rng = rng_for(3, 0, 0);
        (0..200)
            .map(|_| {
                let p = (rng.next_2d().extend(rng.next_f32()) - 0.5) * 8.0;
                let n = (rng.next_2d().extend(rng.next_f32()) - 0.5).normalize_or(Vec3::Y);
                (p, n)
            })
            .collect()
    }

    #[test]
    fn probabilities_sum_to_one_and_keep_a_defensive_share() {
        for with_sky in [false, true] {
            let (powers, bounds) = lights(with_sky);
            let sel = LightSelection::new(&powers, &bounds);
            assert!(sel.is_spatial());
            for (p, n) in points() {
                let sum: f64 = (0..powers.len() as u32)
                    .map(|i| sel.pmf(p, n, i) as f64)
                    .sum();
                assert!((sum - 1.0).abs() < 1e-5, "{sum} at {p}");
                for i in 0..powers.len() as u32 {
                    let floor = POWER_SHARE * sel.by_power().pmf(i as usize);
                    assert!(sel.pmf(p, n, i) >= floor * 0.999, "light {i} at {p}");
                }
                if with_sky {
                    // The sky's share does not depend on the point.
                    assert_eq!(sel.pmf(p, n, 3), sel.pmf(Vec3::ZERO, Vec3::ZERO, 3));
                }
            }
        }
    }

    #[test]
    fn sampling_returns_the_probability_pmf_gives_and_follows_it() {
        let (powers, bounds) = lights(true);
        let sel = LightSelection::new(&powers, &bounds);
        let (p, n) = (Vec3::new(-1.8, 0.0, 0.1), Vec3::Y);
        let pmf: Vec<f32> = (0..4).map(|i| sel.pmf(p, n, i)).collect();
        // Under the beam, which is weak by power, the beam now gets the most picks.
        assert!(pmf[2] > pmf[0] && pmf[2] > 0.3, "{pmf:?}");
        let count = 200_000;
        let mut seen = [0u32; 4];
        let mut rest = [0.0f64; 4];
        for k in 0..count {
            let u = (k as f32 + 0.5) / count as f32;
            let (i, prob, u_rest) = sel.sample(p, n, u);
            assert_eq!(prob.to_bits(), pmf[i].to_bits(), "light {i}");
            assert!((0.0..1.0).contains(&u_rest));
            seen[i] += 1;
            rest[i] += u_rest as f64;
        }
        for i in 0..4 {
            let freq = seen[i] as f32 / count as f32;
            assert!(
                (freq - pmf[i]).abs() < 1e-3,
                "light {i}: {freq} vs {}",
                pmf[i]
            );
            // The rescaled numbers are uniform within each choice.
            let mean = rest[i] / seen[i].max(1) as f64;
            assert!(
                seen[i] == 0 || (mean - 0.5).abs() < 0.01,
                "light {i}: {mean}"
            );
        }
    }

    #[test]
    fn a_light_that_cannot_reach_a_point_gets_only_its_defensive_share() {
        let (powers, bounds) = lights(false);
        let sel = LightSelection::new(&powers, &bounds);
        // Above the downward-facing emitter (light 1) and far outside the beam (light 2).
        let p = Vec3::new(5.0, 6.0, 0.0);
        for i in [1u32, 2] {
            let want = POWER_SHARE * sel.by_power().pmf(i as usize);
            assert!((sel.pmf(p, Vec3::ZERO, i) - want).abs() < 1e-7, "light {i}");
        }
    }

    #[test]
    fn one_finite_light_or_too_many_select_by_power() {
        let sky = EmitterBounds::Environment { irradiance: 3.0 };
        let one = LightSelection::new(&[3.0, 100.0], &[lights(false).1[0], sky]);
        assert!(!one.is_spatial());
        let many = vec![1.0; MAX_EMITTERS + 1];
        let point = LightBounds::omnidirectional(Vec3::ZERO, 0.0, 1.0);
        let bounds = vec![EmitterBounds::Finite(point); many.len()];
        let sel = LightSelection::new(&many, &bounds);
        assert!(!sel.is_spatial());
        assert_eq!(sel.pmf(Vec3::X, Vec3::Y, 3), sel.by_power().pmf(3));
        // With a sun and a sky the infinite lights are weighed, the too many finite ones still
        // by power (no tree is built for them).
        let (mut many, mut bounds) = (many, bounds);
        many.extend([3000.0, 12000.0]);
        bounds.extend([
            EmitterBounds::Directional {
                toward: Vec3::Y,
                irradiance: 3.0,
            },
            sky,
        ]);
        let sel = LightSelection::new(&many, &bounds);
        assert!(sel.is_spatial());
        let (pmf, want) = (sel.pmf(Vec3::X, Vec3::Y, 3), sel.by_power().pmf(3));
        assert!((pmf - want).abs() <= 1e-4 * want, "{pmf} vs {want}");
    }

    #[test]
    fn a_sun_and_a_sky_share_by_the_irradiance_each_delivers() {
        // Sun: irradiance 3 from straight above; sky: π·L = 3 on any surface; and one point
        // light, so the infinite lights have a fixed share (⅔ for two: their power is far
        // larger).
        let point = LightBounds::omnidirectional(Vec3::new(0.0, 3.0, 0.0), 0.0, 1.0);
        let bounds = [
            EmitterBounds::Finite(point),
            EmitterBounds::Directional {
                toward: Vec3::Y,
                irradiance: 3.0,
            },
            EmitterBounds::Environment { irradiance: 3.0 },
        ];
        let sel = LightSelection::new(&[12.0, 3000.0, 12000.0], &bounds);
        assert!(sel.is_spatial());
        // By power the sky gets 4/5 of the infinite share.
        assert!((sel.by_power().pmf(2) / sel.by_power().pmf(1) - 4.0).abs() < 1e-4);
        let p = Vec3::ZERO;
        let share = 2.0 / 3.0;
        let facing = sel.pmf(p, Vec3::Y, 1) / share;
        let grazing = sel.pmf(p, Vec3::new(1.0, 0.01, 0.0).normalize(), 1) / share;
        // Facing the sun: 0.9·½ + 0.1·⅕; on a wall the sun delivers almost nothing.
        assert!((facing - (0.45 + 0.02)).abs() < 1e-5, "{facing}");
        assert!(
            (grazing - (0.9 * 0.03 / 3.03 + 0.02)).abs() < 1e-4,
            "{grazing}"
        );
        for n in [Vec3::Y, Vec3::X, Vec3::ZERO] {
            assert!((sel.pmf(p, n, 0) - (1.0 - share)).abs() < 1e-6);
            let sum: f32 = (0..3).map(|i| sel.pmf(p, n, i)).sum();
            assert!((sum - 1.0).abs() < 1e-6);
        }
        // Two environments relate by power: selected by power, as before.
        let skies = [
            EmitterBounds::Finite(point),
            EmitterBounds::Environment { irradiance: 3.0 },
            EmitterBounds::Environment { irradiance: 1.0 },
        ];
        assert!(!LightSelection::new(&[12.0, 3000.0, 1000.0], &skies).is_spatial());
    }

    #[test]
    fn a_point_on_top_of_a_point_light_picks_that_light() {
        let near = LightBounds::omnidirectional(Vec3::ZERO, 0.0, 1.0);
        let far = LightBounds::omnidirectional(Vec3::new(5.0, 0.0, 0.0), 0.0, 1.0);
        let sel = LightSelection::new(
            &[1.0, 1.0],
            &[EmitterBounds::Finite(near), EmitterBounds::Finite(far)],
        );
        // 1/d² overflows to infinity: the near light takes all but the defensive share.
        let p = Vec3::new(1e-20, 0.0, 0.0);
        assert!(near.importance(p, Vec3::ZERO).is_infinite());
        let want = 1.0 - POWER_SHARE * 0.5;
        assert!((sel.pmf(p, Vec3::ZERO, 0) - want).abs() < 1e-6);
        // A NaN point falls back to power.
        assert_eq!(sel.pmf(Vec3::NAN, Vec3::ZERO, 0), 0.5);
    }

    /// More finite lights than one group weighs: chosen through a tree, with the same
    /// guarantees — the probabilities sum to one, sampling returns them bit for bit and follows
    /// them, and every light keeps a share of its power's (the defensive share at every level
    /// of the tree).
    #[test]
    fn many_lights_go_through_a_tree_and_keep_every_guarantee() {
        let count = 300;
        let mut rng = rng_for(31, 0, 0);
        let mut powers = Vec::new();
        let mut bounds = Vec::new();
        for k in 0..count {
            let c = (rng.next_2d().extend(rng.next_f32()) - 0.5) * 20.0;
            let power = 0.5 + 10.0 * rng.next_f32();
            powers.push(power);
            bounds.push(EmitterBounds::Finite(if k % 2 == 0 {
                LightBounds::omnidirectional(c, 0.0, power)
            } else {
                LightBounds::cone(c, 0.3, power, -Vec3::Y, 1.0, 0.0)
            }));
        }
        let sel = LightSelection::new(&powers, &bounds);
        assert!(sel.is_spatial());
        let Some(Weighing::Tree(tree)) = &sel.split.as_ref().unwrap().finite.bounds else {
            panic!("{count} lights go through a tree");
        };
        // ⌈log₄ 300⌉ levels, give or take the halving's rounding.
        assert!((0..count as u32).all(|i| (4..=6).contains(&tree.depth(i))));
        for (p, n) in points().into_iter().take(40) {
            let pmf: Vec<f32> = (0..count as u32).map(|i| sel.pmf(p, n, i)).collect();
            let sum: f64 = pmf.iter().map(|&x| x as f64).sum();
            assert!((sum - 1.0).abs() < 1e-4, "{sum} at {p}");
            for (i, &x) in pmf.iter().enumerate() {
                let depth = tree.depth(i as u32) as i32;
                let floor = POWER_SHARE.powi(depth) * sel.by_power().pmf(i);
                assert!(x >= floor * 0.999, "light {i} at {p}: {x} < {floor}");
            }
            let mut seen = vec![0u32; count];
            let draws = 100_000;
            for d in 0..draws {
                let u = (d as f32 + 0.5) / draws as f32;
                let (i, prob, u_rest) = sel.sample(p, n, u);
                assert_eq!(prob.to_bits(), pmf[i].to_bits(), "light {i} at {p}");
                assert!((0.0..1.0).contains(&u_rest));
                seen[i] += 1;
            }
            // The most likely light is drawn as often as its probability says.
            let top = (0..count)
                .max_by(|&a, &b| pmf[a].total_cmp(&pmf[b]))
                .unwrap();
            let freq = seen[top] as f32 / draws as f32;
            assert!((freq - pmf[top]).abs() < 2e-3, "{freq} vs {}", pmf[top]);
        }
    }
}
