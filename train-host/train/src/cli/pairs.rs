//! How sources are made from templates on the command line: the flags
//! `pcrnet train` and `pcrnet pairs` share ([`PairArgs`]) and the range
//! parsers behind them.

use anyhow::{Context, bail};
use clap::Args;

use super::super::PairConfig;

/// How sources are made from templates: the same flags, with the same
/// meaning, in `pcrnet train` and `pcrnet pairs` (see
/// [`crate::data`] for the order they apply in).
#[derive(Debug, Clone, Args)]
pub struct PairArgs {
    /// Largest Euler angle per axis (degrees).
    #[arg(long, default_value_t = 45.0, allow_negative_numbers = true)]
    pub max_deg: f32,
    /// Largest translation per axis.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub max_t: f32,
    /// Gaussian noise on the source: a fixed SIGMA or a range LO,HI each
    /// pair draws its sigma from (alone: 0,0.04).
    #[arg(long, num_args = 0..=1, default_missing_value = "0,0.04")]
    pub noise: Option<String>,
    /// Partial source: plane crop keeping a fraction, F or LO,HI (alone: 0.3,0.8).
    #[arg(long, num_args = 0..=1, default_missing_value = "0.3,0.8")]
    pub partial: Option<String>,
    /// Sparse source: random subset keeping a fraction, F or LO,HI (alone: 0.25,0.75).
    #[arg(long, num_args = 0..=1, default_missing_value = "0.25,0.75")]
    pub sparse: Option<String>,
    /// Single-view source: only what a depth camera at a random viewpoint
    /// sees of the object (a z-buffer over the points, see `train::view`).
    #[arg(long)]
    pub single_view: bool,
    /// Share of pairs with no motion at all (source = template up to crops
    /// and noise), so a network learns that f(T, T) is the identity.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub identity_share: f32,
}

impl PairArgs {
    /// The pair configuration, sources centred or not; every range checked
    /// with its flag named.
    pub fn config(&self, centre: bool) -> anyhow::Result<PairConfig> {
        let parsed =
            |v: &Option<String>, flag, parse: fn(&str, &str) -> anyhow::Result<[f32; 2]>| {
                v.as_deref().map(|s| parse(s, flag)).transpose()
            };
        let config = PairConfig {
            max_deg: self.max_deg,
            max_t: self.max_t,
            noise: parsed(&self.noise, "--noise", parse_sigma)?,
            partial: parsed(&self.partial, "--partial", parse_fraction)?,
            sparse: parsed(&self.sparse, "--sparse", parse_fraction)?,
            centre,
            single_view: self.single_view,
            identity_share: self.identity_share,
        };
        config.validate().map_err(anyhow::Error::msg)?;
        Ok(config)
    }
}

/// `X` or `LO,HI` as the two ends of a range (`X` is `X,X`), naming
/// `flag` and the text when a part is not a number.
fn parse_pair(s: &str, flag: &str) -> anyhow::Result<[f32; 2]> {
    let (a, b) = s.split_once(',').unwrap_or((s, s));
    let number = |t: &str| -> anyhow::Result<f32> {
        t.trim()
            .parse()
            .with_context(|| format!("{flag} {s:?}: {t:?} is not a number"))
    };
    Ok([number(a)?, number(b)?])
}

/// Parses a noise level: a fixed `SIGMA` or a range `LO,HI` from which
/// each pair draws its sigma uniformly, `0 <= LO <= HI` (`--noise` of
/// `train`, `pairs` and `upgrade` alike).
pub fn parse_sigma(s: &str, flag: &str) -> anyhow::Result<[f32; 2]> {
    let r = parse_pair(s, flag)?;
    if !(r[0].is_finite() && r[1].is_finite() && 0.0 <= r[0] && r[0] <= r[1]) {
        bail!("{flag} {s:?}: expected SIGMA or LO,HI with 0 <= LO <= HI");
    }
    Ok(r)
}

/// Parses a fraction `F` or a range `LO,HI` with `0 < LO <= HI <= 1`
/// (`--partial`, `--sparse`).
pub fn parse_fraction(s: &str, flag: &str) -> anyhow::Result<[f32; 2]> {
    let [a, b] = parse_pair(s, flag)?;
    if !(0.0 < a && a <= b && b <= 1.0) {
        bail!("{flag} {s:?}: expected F or LO,HI with 0 < LO <= HI <= 1");
    }
    Ok([a, b])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_ranges_and_fractions_name_their_flag() {
        assert_eq!(parse_sigma("0.02", "--noise").unwrap(), [0.02, 0.02]);
        assert_eq!(parse_sigma("0, 0.04", "--noise").unwrap(), [0.0, 0.04]);
        for bad in ["-0.1", "0.04,0.01", "nan", "inf", "x"] {
            let e = parse_sigma(bad, "--noise").unwrap_err();
            assert!(format!("{e:#}").starts_with("--noise"), "{e:#}");
        }
        assert_eq!(parse_fraction("0.3,0.8", "--partial").unwrap(), [0.3, 0.8]);
        assert_eq!(parse_fraction("1", "--sparse").unwrap(), [1.0, 1.0]);
        for bad in ["0", "1.5", "0.8,0.3", "x"] {
            let e = parse_fraction(bad, "--partial").unwrap_err();
            assert!(format!("{e:#}").starts_with("--partial"), "{e:#}");
        }
    }
}
