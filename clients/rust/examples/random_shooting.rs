//! A planner next to the model, on the client side: model-predictive control
//! by random shooting over a served model. Each control step draws
//! `--candidates` action sequences of `--horizon` steps uniformly in the
//! model's action box, has the server score them all in one `score` call
//! (penalised returns r − λ·η over `--particles` samples, truncated at ε(h, α)),
//! takes the first action of the best, and steps the model with it. (The
//! server's own `plan` route runs CEM, iCEM or MPPI in one call instead.)
//!
//!   nuno-server --models models &
//!   cargo run --release -p nuno-client --example random_shooting -- --steps 20

use clap::Parser;
use nuno_client::{ClientError, Rows, ScoreRequest, StepRequest, blocking::Client};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[derive(Debug, Parser)]
struct Args {
    #[arg(long, default_value = "http://127.0.0.1:8080")]
    server: String,
    #[arg(long, default_value = "hopper-random")]
    model: String,
    #[arg(long, env = "NUNO_TOKEN")]
    token: Option<String>,
    /// Control steps to take.
    #[arg(long, default_value_t = 50)]
    steps: usize,
    /// Action sequences scored per control step.
    #[arg(long, default_value_t = 256)]
    candidates: usize,
    #[arg(long, default_value_t = 10)]
    horizon: usize,
    /// Samples of each sequence's rollout.
    #[arg(long, default_value_t = 4)]
    particles: usize,
    /// λ of the penalised return.
    #[arg(long, default_value_t = 1.0)]
    penalty: f64,
    /// α of the truncation threshold ε(h, α) from the model's table.
    #[arg(long, default_value_t = 0.99)]
    alpha: f64,
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

fn main() -> Result<(), ClientError> {
    let args = Args::parse();
    let mut client = Client::new(&args.server)?;
    if let Some(token) = &args.token {
        client = client.with_token(token);
    }
    let model = client.model(&args.model)?.summary;
    let (obs_dim, act_dim) = (model.obs_dim, model.act_dim);
    // An upright start for the locomotion tasks (the first observation is the height).
    let mut state = vec![0.0f32; obs_dim];
    state[0] = 1.25;
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    let mut total = 0.0;
    for t in 0..args.steps {
        let sequences: Vec<Rows> = (0..args.candidates)
            .map(|_| {
                let actions = (0..args.horizon * act_dim)
                    .map(|i| {
                        rng.random_range(
                            model.action_low[i % act_dim]..=model.action_high[i % act_dim],
                        )
                    })
                    .collect();
                Rows::new(actions, act_dim)
            })
            .collect();
        let mut score = ScoreRequest::new(
            Rows::new(state.clone(), obs_dim),
            vec![sequences.clone()],
            args.horizon,
        );
        (score.particles, score.penalty, score.alpha, score.seed) =
            (args.particles, args.penalty, Some(args.alpha), rng.random());
        let scores = &client.score(&args.model, &score)?.scores[0];
        let best = (0..scores.len())
            .max_by(|&a, &b| {
                scores[a]
                    .penalized_return
                    .total_cmp(&scores[b].penalized_return)
            })
            .unwrap_or(0);
        let action = sequences[best].values()[..act_dim].to_vec();
        let mut step = StepRequest::new(
            Rows::new(state.clone(), obs_dim),
            Rows::new(action, act_dim),
        );
        (step.penalty, step.seed) = (args.penalty, rng.random());
        let answer = client.step(&args.model, &step)?;
        state = answer.next_states[0][0].clone();
        total += f64::from(answer.rewards[0][0]);
        println!(
            "step {t:3}: best of {} penalised return {:8.3}, reward {:6.3}, η {:.3}",
            args.candidates, scores[best].penalized_return, answer.rewards[0][0], answer.eta[0]
        );
        if answer.terminals[0][0] {
            println!("terminated by the model's rule");
            break;
        }
    }
    println!("return over the model: {total:.2}");
    Ok(())
}
