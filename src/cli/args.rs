//! Option values several subcommands share, typed: clap parses and checks
//! them (a bad value is a usage error naming the option and what it
//! accepts), and `--help` lists the choices.

use std::str::FromStr;

use clap::ValueEnum;
use topspin_core::logo::GapRule;
use topspin_core::logo::LogoMethod;
use topspin_sim::Setting;
use topspin_sim::render::BallColour;

/// `--setting all|NAME[,NAME…]`: launcher settings, in the order given.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings(pub Vec<Setting>);

impl FromStr for Settings {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s.trim().eq_ignore_ascii_case("all") {
            return Ok(Settings(Setting::ALL.to_vec()));
        }
        s.split(',').map(|n| n.parse::<Setting>().map_err(|e| e.to_string())).collect::<Result<_, _>>().map(Settings)
    }
}

/// Which ball colours.
#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum Colours {
    /// Orange balls.
    Orange,
    /// White balls.
    White,
    /// Both, orange first.
    Both,
}

impl Colours {
    /// The colours, in order.
    pub fn list(self) -> Vec<BallColour> {
        match self {
            Colours::Orange => vec![BallColour::Orange],
            Colours::White => vec![BallColour::White],
            Colours::Both => BallColour::ALL.to_vec(),
        }
    }
}

/// Where the logo's centre is taken from.
#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum LogoMethodChoice {
    /// The paper's centroid, uncorrected.
    Centroid,
    /// The paper's centroid with the circular-segment correction.
    Segment,
    /// Area-weighted centroid plus the segment correction.
    Weighted,
    /// The CNN of `--model`.
    Cnn,
}

impl LogoMethodChoice {
    /// The background method, or `None` for the CNN.
    pub fn background(self) -> Option<LogoMethod> {
        match self {
            LogoMethodChoice::Centroid => Some(LogoMethod::Centroid),
            LogoMethodChoice::Segment => Some(LogoMethod::Segment),
            LogoMethodChoice::Weighted => Some(LogoMethod::Weighted),
            LogoMethodChoice::Cnn => None,
        }
    }
}

/// How gaps of two or more unseen frames are bridged.
#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum GapRuleChoice {
    /// The large angle (the paper).
    Paper,
    /// The angle in the rotation's direction plus the predicted turns.
    Directed,
}

impl From<GapRuleChoice> for GapRule {
    fn from(c: GapRuleChoice) -> Self {
        match c {
            GapRuleChoice::Paper => GapRule::Paper,
            GapRuleChoice::Directed => GapRule::Directed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_parse_all_or_a_list() {
        assert_eq!("all".parse::<Settings>().unwrap().0, Setting::ALL.to_vec());
        let two: Settings = format!("{},{}", Setting::ALL[3], Setting::ALL[0]).parse().unwrap();
        assert_eq!(two.0, vec![Setting::ALL[3], Setting::ALL[0]]);
        assert!("topspin-nope".parse::<Settings>().is_err());
    }

    #[test]
    fn every_logo_method_but_the_cnn_is_a_background_method() {
        for c in LogoMethodChoice::value_variants() {
            assert_eq!(c.background().is_none(), *c == LogoMethodChoice::Cnn, "{c:?}");
        }
        assert_eq!(Colours::Both.list(), BallColour::ALL.to_vec());
    }
}
