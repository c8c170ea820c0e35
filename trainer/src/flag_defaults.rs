//! A subcommand's `Args` with every flag at its default, for callers that
//! build a run in code (the experiment runner): the same defaults a typed
//! command gets, so a caller sets fields, never restates a default.

/// `A` parsed from `required`, the subcommand's name then its required flags
/// with their values; every other field holds its flag's default.
pub fn with_defaults<A: clap::Args + clap::FromArgMatches>(required: &[&str]) -> A {
    let command = A::augment_args(clap::Command::new("nuno-trainer"));
    let matches = command
        .try_get_matches_from(required)
        .unwrap_or_else(|e| panic!("{}'s required flags: {e}", required[0]));
    A::from_arg_matches(&matches).unwrap_or_else(|e| panic!("{}'s defaults: {e}", required[0]))
}
