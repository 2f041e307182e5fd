//! Choosing among starting poses: each start gets a few ICP iterations
//! (screening), the best goes on to the full ICP. [`resolve`] is flip
//! resolution about the network's pose; [`resolve_starts`] the same search
//! over any list of starts (the yaw sweep of [`crate::sweep`]).

use super::{Fit, IcpSettings, Subset, icp, icp_run, score};
use crate::error::{Error, Result};
use crate::pose::Pose;
use crate::template::Template;

/// The result of [`resolve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resolved {
    /// The chosen pose (model frame).
    pub pose: Pose,
    /// Its fit.
    pub fit: Fit,
    /// Which start it came from: 0 the given pose, `k` the pose followed by turn `k - 1`.
    pub hypothesis: usize,
    /// ICP iterations run from that start.
    pub icp_iterations: usize,
    /// The best start that ended elsewhere, refined as far as the chosen
    /// one: what [`crate::ambiguity`] compares the chosen pose with.
    /// `None` when there is none: one start, or flip resolution dropped
    /// every turned start ([`SCREEN_DROP`]).
    pub rival: Option<Rival>,
}

/// A refined start other than the chosen one (see [`Resolved::rival`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rival {
    /// Its pose (model frame).
    pub pose: Pose,
    /// Its fit, on the same points as the chosen pose's.
    pub fit: Fit,
    /// Which start it came from (numbered as [`Resolved::hypothesis`]).
    pub hypothesis: usize,
}

impl Resolved {
    /// This result as the rival of another.
    fn as_rival(&self) -> Rival {
        Rival {
            pose: self.pose,
            fit: self.fit,
            hypothesis: self.hypothesis,
        }
    }
}

/// [`resolve_starts`] refines a second start further when its screened
/// residual is at most this many times the best's and its pose lies at
/// least [`RIVAL_MIN_TURN_COS`] away: a start that might fit as well.
pub const RIVAL_SCREEN_RATIO: f32 = 1.5;

/// A screened start is a rival only if its rotation differs from the best's
/// by at least 10 degrees: `|q_best . q_rival|` at most `cos(10 deg / 2)`.
/// Nearer starts fell into the same fit.
pub const RIVAL_MIN_TURN_COS: f32 = 0.996_194_7;

/// Iterations after which flip resolution ([`resolve`]) checks a turned
/// start's residual ([`SCREEN_DROP`]).
pub const SCREEN_CHECK: usize = 3;

/// Flip resolution ([`resolve`]) drops a turned start whose residual after
/// [`SCREEN_CHECK`] ICP iterations is above this many times the lowest
/// residual reached so far (the network's finished pose, or an earlier
/// turned start's screening): it is not screened on. A turned start wins
/// only below [`FLIP_MARGIN`] times the network's residual; one at twice
/// the lowest after three of its ten screening iterations almost never
/// gets there in the seven left.
///
/// Measured (session 52) on the `trust` experiment's sets at 1,000 pairs
/// each (shipped model, or the held-out classes' i-PCRNet; device K = 10,
/// noise 0.01), against screening every start to the end: ModelNet10,
/// resampled, airplanes and held-out classes the same success (998, 965,
/// 988, 989), the same poses more than 5 degrees off (1, 16, 11, 11; of
/// them reliable 1, 7, 0, 4) and good poses flagged (0, 134, 0, 0); 9 of
/// the 4,000 poses changed, none by more than half a degree for the worse.
/// Dropped: 89%, 19%, 67% and 84% of the turned starts. At 1.5 times,
/// 94% to 61% dropped, but an airplane and a held-out pose flipped by 180
/// degrees; checking after 2 iterations at 1.5 times flipped more.
/// The default registration on the Cortex-M4F (the QEMU harness, 512
/// points): 22.7 M -> 14.4 M instructions on the shipped demo source (the
/// template's own points: every other start is dropped), 24.2 M -> 15.6 M
/// on it with noise of standard deviation 0.01 (the harness's noisy demo
/// source). The check costs one scoring a start: with nothing dropped,
/// 24.0 M.
///
/// A dropped start cannot be the result's [`Resolved::rival`], which the
/// turn ambiguity of [`crate::ambiguity`] compares with: the `ambiguity`
/// experiment (200 pairs a set) reported the same on generated symmetric
/// shapes (83 of the 84 reliable poses more than 5 degrees off ambiguous)
/// and on chairs, toilets, sofas and beds (6 of 200), and more on tables
/// and night stands (86 of 200 against 74, all within 5 degrees: square
/// and round furniture).
pub const SCREEN_DROP: f32 = 2.0;

/// Screened starts [`Search::best_of`] keeps to find a rival among.
const KEPT: usize = 4;

/// Whether two rotations differ by more than the rival's least turn.
pub(crate) fn apart(a: &Pose, b: &Pose) -> bool {
    a.rotation_cosine(b) <= RIVAL_MIN_TURN_COS
}

/// A turned hypothesis replaces the network's own pose only when its
/// residual is below this share of the network's (see [`resolve`]).
///
/// Measured on 200 ModelNet10 test pairs (shipped model, noise 0.01): with
/// sources resampled from the surface (no point shared with the template),
/// plain "lowest residual wins" picked a symmetric flip of desks, tables
/// and dressers in 13% of the pairs (AUC 0.86 against 0.98 for the network's
/// pose alone), because sampling noise then hides the small asymmetries;
/// with shared points the right pose's residual is near zero and any margin
/// keeps it.
pub const FLIP_MARGIN: f32 = 0.7;

/// What a caller who knows more about the source than its points adds to
/// flip resolution ([`resolve`]; poses in the model frame, source onto
/// template). A cut single view seen from a known viewpoint knows both
/// ([`crate::viewed`]).
pub trait Guide {
    /// Where a start begins its screening: by default where it is.
    fn place(&mut self, start: Pose) -> Pose {
        start
    }

    /// Whether a screened turned start may finish: by default every one.
    /// A guide that refuses any start must also say so
    /// ([`Guide::may_refuse`]), or flip resolution may drop the start it
    /// would take.
    fn accept(&mut self, _pose: &Pose) -> bool {
        true
    }

    /// Whether [`Guide::accept`] may refuse a start: by default not. Flip
    /// resolution drops no start early under a guide that may
    /// ([`SCREEN_DROP`]).
    fn may_refuse(&self) -> bool {
        false
    }
}

/// No guide: the starts as given, every screened start may finish.
#[derive(Debug, Clone, Copy, Default)]
pub struct Unguided;

impl Guide for Unguided {}

/// A guide when there is one, else none ([`Unguided`]).
impl<G: Guide> Guide for Option<G> {
    fn place(&mut self, start: Pose) -> Pose {
        match self {
            Some(g) => g.place(start),
            None => start,
        }
    }

    fn accept(&mut self, pose: &Pose) -> bool {
        self.as_mut().is_none_or(|g| g.accept(pose))
    }

    fn may_refuse(&self) -> bool {
        self.as_ref().is_some_and(|g| g.may_refuse())
    }
}

/// One search: the template, the used points, the screening and the
/// finishing ICP settings, the scoring distance.
struct Search<'a, 't, 's> {
    template: &'a Template<'t>,
    subset: &'a Subset<'s>,
    first: IcpSettings,
    rest: IcpSettings,
    max_distance: f32,
}

impl<'a, 't, 's> Search<'a, 't, 's> {
    fn new(
        template: &'a Template<'t>,
        subset: &'a Subset<'s>,
        screen: usize,
        icp_settings: &IcpSettings,
        max_distance: f32,
    ) -> Self {
        let first = IcpSettings {
            iterations: screen.min(icp_settings.iterations),
            ..*icp_settings
        };
        let rest = IcpSettings {
            iterations: icp_settings.iterations.saturating_sub(first.iterations),
            ..*icp_settings
        };
        Search {
            template,
            subset,
            first,
            rest,
            max_distance,
        }
    }

    /// ICP from `from` on `on` with `settings`, then scored.
    fn refine(
        &self,
        from: Pose,
        hypothesis: usize,
        settings: &IcpSettings,
        on: &Subset<'_>,
    ) -> Result<Resolved> {
        let (pose, icp_iterations) = icp(self.template, on, from, settings);
        self.scored(pose, hypothesis, icp_iterations, on)
    }

    /// `pose` (reached from start `hypothesis` in `icp_iterations`)
    /// scored on `on`; a non-finite residual is an error.
    fn scored(
        &self,
        pose: Pose,
        hypothesis: usize,
        icp_iterations: usize,
        on: &Subset<'_>,
    ) -> Result<Resolved> {
        let fit = score(self.template, on, &pose, self.max_distance);
        if fit.residual.is_finite() {
            Ok(Resolved {
                pose,
                fit,
                hypothesis,
                icp_iterations,
                rival: None,
            })
        } else {
            Err(Error::NonFiniteResult)
        }
    }

    /// A start's screening: [`SCREEN_CHECK`] ICP iterations, scored;
    /// unless ICP stopped on its own there, or the start is dropped, the
    /// rest of `first`'s iterations from where it got to (the same pose,
    /// bit for bit, as one run of them all). With `bound` (the lowest
    /// residual a start has reached in this search) a start whose residual
    /// after those iterations is above [`SCREEN_DROP`] times it is dropped:
    /// `None`.
    fn screen(
        &self,
        from: Pose,
        hypothesis: usize,
        bound: Option<f32>,
    ) -> Result<Option<Resolved>> {
        let Some(bound) = bound.filter(|_| self.first.iterations > SCREEN_CHECK) else {
            return self
                .refine(from, hypothesis, &self.first, self.subset)
                .map(Some);
        };
        let check = IcpSettings {
            iterations: SCREEN_CHECK,
            ..self.first
        };
        let run = icp_run(self.template, self.subset, from, &check);
        let checked = self.scored(run.pose, hypothesis, run.iterations, self.subset)?;
        if run.stopped {
            return Ok(Some(checked));
        }
        if checked.fit.residual > SCREEN_DROP * bound {
            return Ok(None);
        }
        let rest = IcpSettings {
            iterations: self.first.iterations - SCREEN_CHECK,
            ..self.first
        };
        let more = self.refine(run.pose, hypothesis, &rest, self.subset)?;
        Ok(Some(Resolved {
            icp_iterations: run.iterations + more.icp_iterations,
            ..more
        }))
    }

    /// A finalist continues ICP; one whose screening stopped on its own
    /// (converged, or too few pairs) is done.
    fn finish(&self, r: Resolved) -> Result<Resolved> {
        if self.rest.iterations == 0 || r.icp_iterations < self.first.iterations {
            return Ok(r);
        }
        let more = self.refine(r.pose, r.hypothesis, &self.rest, self.subset)?;
        Ok(Resolved {
            icp_iterations: r.icp_iterations + more.icp_iterations,
            ..more
        })
    }

    /// Screens every `(hypothesis, start)` from where `guide` places it;
    /// the one with the lowest residual (the first on a tie) that `guide`
    /// accepts finishes (the lowest when it accepts none; see [`resolve`]).
    fn best_of(
        &self,
        starts: impl IntoIterator<Item = (usize, Pose)>,
        guide: &mut impl Guide,
        dropping: Dropping,
    ) -> Result<Option<Screened>> {
        // The lowest residuals so far, ascending (ties keep the earlier
        // start), at most one per fit: a start that ends near a kept one
        // (not [`apart`]) replaces it only if lower.
        let mut kept: [Option<Resolved>; KEPT] = [None; KEPT];
        for (hypothesis, from) in starts {
            let lowest = match (dropping, kept[0]) {
                (Dropping::Never, _) => None,
                (Dropping::Above(b), Some(k)) => Some(b.min(k.fit.residual)),
                (Dropping::Above(b), None) => Some(b),
            };
            let Some(r) = self.screen(guide.place(from), hypothesis, lowest)? else {
                continue;
            };
            let same = kept
                .iter()
                .position(|k| k.is_some_and(|k| !apart(&k.pose, &r.pose)));
            let slot = match same {
                Some(i) if kept[i].is_some_and(|k| r.fit.residual < k.fit.residual) => i,
                Some(_) => continue,
                None => KEPT - 1,
            };
            if kept[slot].is_some_and(|k| r.fit.residual >= k.fit.residual) {
                continue;
            }
            kept[slot] = Some(r);
            // Back into ascending order: move it up past higher residuals.
            let mut i = slot;
            while i > 0
                && kept[i - 1]
                    .is_none_or(|k| kept[i].is_some_and(|r| r.fit.residual < k.fit.residual))
            {
                kept.swap(i - 1, i);
                i -= 1;
            }
        }
        let Some(lowest) = kept[0] else {
            return Ok(None);
        };
        let best = kept
            .iter()
            .flatten()
            .find(|k| guide.accept(&k.pose))
            .copied()
            .unwrap_or(lowest);
        let rival = kept
            .into_iter()
            .flatten()
            .find(|r| apart(&best.pose, &r.pose));
        Ok(Some(Screened {
            screened_residual: best.fit.residual,
            best: self.finish(best)?,
            rival,
        }))
    }
}

/// Whether [`Search::best_of`] drops starts after [`SCREEN_CHECK`]
/// iterations ([`SCREEN_DROP`]).
#[derive(Debug, Clone, Copy)]
enum Dropping {
    /// Every start is screened to the end.
    Never,
    /// Starts are dropped above [`SCREEN_DROP`] times the lowest residual
    /// reached: by an earlier start of the search, or the one given (a
    /// start already refined outside it).
    Above(f32),
}

/// What [`Search::best_of`] found.
struct Screened {
    /// The best start, finished.
    best: Resolved,
    /// Its residual when screened.
    screened_residual: f32,
    /// The best screened start [`apart`] from it (among the [`KEPT`]
    /// lowest distinct fits), not finished.
    rival: Option<Resolved>,
}

/// Flip resolution. Starts are `start` (the network's pose) and `start`
/// followed by each of the first `hypotheses - 1` template turns. The
/// network's start and each turned start get `screen` ICP iterations,
/// except that a turned start whose residual after [`SCREEN_CHECK`] of
/// them is above [`SCREEN_DROP`] times the lowest reached so far is
/// dropped (not under a guide that [`Guide::may_refuse`]). The
/// network's start and the best-scoring turned start then continue ICP up
/// to `icp.iterations` in all.
/// The best turned pose wins only if its residual is below
/// [`FLIP_MARGIN`] times the network's: the network's answer stands unless
/// the template's points clearly favour a turn; the finalist that loses is
/// the result's [`Resolved::rival`] (none when every turned start was
/// dropped). With `screen >= icp.iterations` every start that is not
/// dropped gets the full ICP.
///
/// `guide` adds what the caller knows besides the points ([`Guide`]):
/// every start (the network's and each turned one) begins where
/// [`Guide::place`] puts it, and screening finishes the lowest-residual
/// turned start [`Guide::accept`] takes (the lowest when it takes none);
/// the margin against the network's pose stays the residual's.
/// [`Unguided`] leaves the search as it was, bit for bit. (Measured on the
/// `resampled` experiment's single-view sets, 200 pairs each, session 50:
/// letting the test also overrule the margin (a turned finalist the view
/// accepts beating a network pose it does not) raised success 0.760 ->
/// 0.765 and 0.635 -> 0.665, but picked 180-degree turns of symmetric
/// shapes that explain the view as well: reliable poses more than 5
/// degrees off 3 -> 9 and 8 -> 12. The screening choice alone: 0.765 and
/// 0.635, 3 and 8.)
///
/// Turned starts are screened on every used point. Screening them on half
/// the points (sessions 40 to 42) took the default registration on the
/// Cortex-M4F from 80.7 M to 55.7 M instructions with the same ModelNet10,
/// resampled and airplane rows of the `trust` experiment, but the held-out
/// classes' row (i-PCRNet trained on five other classes) fell from AUC
/// 0.975 to 0.960 (three more poses above 30 degrees), which was not
/// measured then: with the closest-point table, all points cost 49.9 M
/// (half of them 39.8 M), both with the network on every source point
/// (35.7 M since it encodes 256 of them). Two finalist turns gave 0.9973 on ModelNet10,
/// but a second finalist that does not converge grinds through the whole
/// ICP budget (K = 4: 64 M instead of 46 M, before the table), so one it is.
#[allow(clippy::too_many_arguments)]
pub fn resolve(
    template: &Template<'_>,
    subset: &Subset<'_>,
    start: Pose,
    hypotheses: usize,
    screen: usize,
    icp_settings: &IcpSettings,
    max_distance: f32,
    guide: &mut impl Guide,
) -> Result<Resolved> {
    let search = Search::new(template, subset, screen, icp_settings, max_distance);
    let turns = template.turns();
    let count = hypotheses.min(turns.len().saturating_add(1)).max(1);
    let first = guide.place(start);
    let network = search.finish(search.refine(first, 0, &search.first, subset)?)?;
    // A guide that may refuse the lowest screened start needs every start
    // screened to the end: the one it takes can lie far above the lowest.
    let dropping = if guide.may_refuse() {
        Dropping::Never
    } else {
        Dropping::Above(network.fit.residual)
    };
    let turned = turns
        .iter()
        .enumerate()
        .take(count - 1)
        .map(|(k, &rotation)| {
            let turn = Pose {
                rotation,
                translation: [0.0; 3],
            };
            (k + 1, start.then(&turn))
        });
    let Some(Screened { best: t, .. }) = search.best_of(turned, guide, dropping)? else {
        return Ok(network);
    };
    Ok(if t.fit.residual < FLIP_MARGIN * network.fit.residual {
        Resolved {
            rival: Some(network.as_rival()),
            ..t
        }
    } else {
        Resolved {
            rival: Some(t.as_rival()),
            ..network
        }
    })
}

/// The best of `starts` (model frame, numbered by their hypothesis): each
/// gets `screen` ICP iterations (none is dropped: [`SCREEN_DROP`] was
/// measured on flip resolution only), the one with the lowest residual
/// continues up to `icp.iterations` in all. The best start that
/// ended elsewhere ([`RIVAL_MIN_TURN_COS`]) gets `screen` more iterations
/// on every used point when its screened residual is within
/// [`RIVAL_SCREEN_RATIO`] of the best's: it is the result's
/// [`Resolved::rival`]. Measured on the `scene` experiment (ToF / RGB-D,
/// the sweep): this finds the same ambiguous frames as finishing the rival
/// to the full budget (5 / 7 of the 9 / 12 reliable poses more than 5
/// degrees off) for 10% more host time instead of 25%; scoring the screened
/// rival again without more ICP found 4 / 5. An empty list is
/// [`Error::InvalidOption`]. Each start begins where `guide` places it,
/// and the best is the lowest-residual one it accepts (the lowest when it
/// accepts none).
pub fn resolve_starts(
    template: &Template<'_>,
    subset: &Subset<'_>,
    starts: impl IntoIterator<Item = (usize, Pose)>,
    screen: usize,
    icp_settings: &IcpSettings,
    max_distance: f32,
    guide: &mut impl Guide,
) -> Result<Resolved> {
    let search = Search::new(template, subset, screen, icp_settings, max_distance);
    let found = search
        .best_of(starts, guide, Dropping::Never)?
        .ok_or(Error::InvalidOption {
            what: "a sweep needs at least one start",
        })?;
    let rival = match found.rival {
        Some(r) if r.fit.residual <= RIVAL_SCREEN_RATIO * found.screened_residual => {
            let more = search.refine(r.pose, r.hypothesis, &search.first, search.subset)?;
            Some(more.as_rival())
        }
        _ => None,
    };
    Ok(Resolved {
        rival,
        ..found.best
    })
}
