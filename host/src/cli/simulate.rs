//! `jointid simulate --out FILE.csv`: runs the closed-loop joint simulator ([`crate::sim`])
//! on the firmware's excitation and writes a capture CSV (DESIGN.md §5) that every analysis
//! command reads, with the excitation config in its `# key=value` comments so the periods
//! can be found again. Optionally writes the whole simulator configuration as JSON.

use std::io::Write;
use std::path::PathBuf;

use clap::{Args, ValueEnum};
use serde::Serialize;

use super::{print_json, CmdResult, Context, Outcome};
use crate::data::{excitation_comment_lines, ExcitationConfig, SignalKind};
use crate::sim::{
    parse_effects, simulate_excitation, Integrator, Mechanism, Plant, PlantKind, SensorConfig,
    SimConfig,
};

/// Excitation signal kind on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum KindArg {
    /// special odd multisine (seed 000 eq. (4)), for the linearity check
    SpecialOdd,
    /// random-phase full odd multisine
    RandomOdd,
    /// band-limited noise (validation data)
    Noise,
}

/// Arguments of `jointid simulate`.
#[derive(Debug, Clone, Args)]
pub struct SimulateArgs {
    /// capture CSV to write
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// plant: rigid, two_mass, three_mass, four_mass, nonlinear_two_mass
    #[arg(long, value_name = "KIND", default_value = "three_mass", value_parser = parse_plant)]
    pub plant: PlantKind,
    /// effect spec, repeatable: `name` or `name:key=value,...` (e.g. `backlash:width=2e-5`),
    /// or `none`; names: coulomb_friction, backlash, nonlinear_stiffness, extra_mode,
    /// time_delay, torque_ripple
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
    /// excitation kind (core's paper default otherwise)
    #[arg(long, value_enum, default_value_t = KindArg::SpecialOdd)]
    pub kind: KindArg,
    /// RMS of the motor-angle reference [rad] (default: core's paper default, 0.02)
    #[arg(long, value_name = "RAD")]
    pub rms: Option<f32>,
    /// full-amplitude excitation periods (default: core's paper default, 4)
    #[arg(long, value_name = "P", value_parser = clap::value_parser!(u32).range(1..))]
    pub periods: Option<u32>,
    /// excitation seed (phases / noise)
    #[arg(long, value_name = "N")]
    pub excitation_seed: Option<u64>,
    /// seed of the simulator's noise and disturbance
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
    /// perfect sensors: no quantisation, no noise, no disturbance
    #[arg(long)]
    pub ideal_sensors: bool,
    /// velocity and torque feedforward in the robot's controller
    #[arg(long)]
    pub feedforward: bool,
    /// event-aware RK4 substeps per sample when the plant is nonlinear (used in the samples
    /// with contact or stick–slip events; the others take one exponential step)
    #[arg(long, value_name = "M", value_parser = clap::value_parser!(u32).range(1..))]
    pub substeps: Option<u32>,
    /// also write the whole simulator configuration (every parameter) as JSON here
    #[arg(long, value_name = "FILE")]
    pub params_json: Option<PathBuf>,
}

fn parse_plant(s: &str) -> Result<PlantKind, String> {
    s.parse()
}

#[derive(Serialize)]
struct Report<'a> {
    file: String,
    params_json: Option<String>,
    samples: usize,
    duration_s: f64,
    integrator: Integrator,
    saturated_samples: u64,
    u_rms: f64,
    theta_m_rms: f64,
    resonances_hz: Vec<f64>,
    anti_resonances_hz: Vec<f64>,
    config: &'a SimConfig,
}

fn rms(x: &[f64]) -> f64 {
    let n = x.len().max(1) as f64;
    let m = x.iter().sum::<f64>() / n;
    (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n).sqrt()
}

/// The simulator configuration and the excitation these arguments describe.
///
/// # Errors
/// Bad effect specs.
pub fn configure(
    args: &SimulateArgs,
) -> Result<(SimConfig, ExcitationConfig), Box<dyn std::error::Error + Send + Sync>> {
    let mut cfg = SimConfig {
        plant: Plant::new(args.plant),
        effects: parse_effects(&args.effects)?,
        seed: args.seed,
        ..SimConfig::default()
    };
    if args.ideal_sensors {
        cfg.sensors = SensorConfig::ideal();
    }
    cfg.controller.feedforward = args.feedforward;
    if let Some(m) = args.substeps {
        cfg.integration.substeps = m;
    }
    let mut exc = ExcitationConfig::paper_default();
    exc.kind = match args.kind {
        KindArg::SpecialOdd => SignalKind::SpecialOddMultisine,
        KindArg::RandomOdd => SignalKind::RandomOddMultisine,
        KindArg::Noise => SignalKind::BandLimitedNoise,
    };
    if let Some(r) = args.rms {
        exc.rms_rad = r;
    }
    if let Some(p) = args.periods {
        exc.periods = p;
    }
    if let Some(s) = args.excitation_seed {
        exc.seed = s;
    }
    cfg.sample_rate_hz = f64::from(exc.fs_hz);
    Ok((cfg, exc))
}

/// Runs `jointid simulate`.
///
/// # Errors
/// Bad effect specs, invalid configuration or excitation, write errors.
pub fn run(args: &SimulateArgs, ctx: &mut Context<'_>) -> CmdResult {
    let (cfg, exc) = configure(args)?;
    let out = simulate_excitation(&cfg, &exc)?;
    let effects: Vec<String> = cfg.effects.iter().map(|e| e.to_string()).collect();
    let mut comments = excitation_comment_lines(&exc);
    comments.push_str(&format!(
        "# sim_plant={}\n# sim_effects={}\n# sim_seed={}\n",
        cfg.plant.kind.name(),
        if effects.is_empty() {
            "none".to_string()
        } else {
            effects.join(";")
        },
        cfg.seed
    ));
    let file =
        std::fs::File::create(&args.out).map_err(|e| format!("{}: {e}", args.out.display()))?;
    let mut w = std::io::BufWriter::new(file);
    out.write_csv(&mut w, &comments)
        .and_then(|()| w.flush())
        .map_err(|e| format!("{}: {e}", args.out.display()))?;
    if let Some(p) = &args.params_json {
        std::fs::write(p, cfg.params_json()? + "\n")
            .map_err(|e| format!("{}: {e}", p.display()))?;
    }
    let modes = Mechanism::new(&cfg.plant, &cfg.effects).modal_frequencies();
    let report = Report {
        file: args.out.display().to_string(),
        params_json: args.params_json.as_ref().map(|p| p.display().to_string()),
        samples: out.len(),
        duration_s: out.len() as f64 * out.sample_interval_s,
        integrator: out.integrator,
        saturated_samples: out.saturated_samples,
        u_rms: rms(&out.u),
        theta_m_rms: rms(&out.theta_m),
        resonances_hz: modes.resonances_hz,
        anti_resonances_hz: modes.anti_resonances_hz,
        config: &cfg,
    };
    if ctx.json {
        print_json(ctx.out, &report)?;
    } else {
        let o = &mut *ctx.out;
        writeln!(
            o,
            "wrote {} ({} samples, {:.2} s at {} Hz)",
            report.file, report.samples, report.duration_s, exc.fs_hz
        )?;
        writeln!(
            o,
            "plant {}, effects: {}",
            cfg.plant.kind.name(),
            if effects.is_empty() {
                "none".to_string()
            } else {
                effects.join(" ")
            }
        )?;
        let fmt = |v: &[f64]| {
            v.iter()
                .map(|f| format!("{f:.2}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        writeln!(
            o,
            "modes seen from the motor: resonances [{}] Hz, anti-resonances [{}] Hz",
            fmt(&report.resonances_hz),
            fmt(&report.anti_resonances_hz)
        )?;
        writeln!(
            o,
            "integrator {:?}, u rms {:.4} N·m, theta_m rms {:.5} rad, saturated samples {}",
            report.integrator, report.u_rms, report.theta_m_rms, report.saturated_samples
        )?;
        if let Some(p) = &report.params_json {
            writeln!(o, "parameters: {p}")?;
        }
    }
    Ok(Outcome::Ok)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{default_loaders, Cli, Command};
    use crate::data::{load_csv, ColumnMap};
    use clap::Parser;

    fn temp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("jointid-sim-{}-{name}", std::process::id()))
    }

    #[test]
    fn simulate_writes_a_capture_csv_that_data_reads_back() {
        let csv = temp("out.csv");
        let json = temp("params.json");
        let cli = Cli::try_parse_from([
            "jointid",
            "simulate",
            "--out",
            csv.to_str().unwrap(),
            "--effect",
            "backlash:width=3e-5",
            "--effect",
            "time_delay",
            "--periods",
            "1",
            "--params-json",
            json.to_str().unwrap(),
        ])
        .unwrap();
        let Command::Simulate(args) = &cli.command else {
            panic!("parsed {:?}", cli.command)
        };
        let loaders = default_loaders();
        let mut buf = Vec::new();
        let outcome = crate::cli::run(
            &cli,
            &mut Context {
                json: false,
                loaders: &loaders,
                out: &mut buf,
            },
        )
        .unwrap();
        assert_eq!(outcome, Outcome::Ok);
        let text = String::from_utf8(buf).unwrap();
        assert!(
            text.contains("effects: backlash:width=0.00003 time_delay:samples=1.5"),
            "{text}"
        );
        let ds = load_csv(&csv, &ColumnMap::capture()).unwrap();
        let (cfg, exc) = configure(args).unwrap();
        assert_eq!(ds.excitation, Some(exc));
        assert_eq!(
            ds.meta.get("sim_plant").map(String::as_str),
            Some("three_mass")
        );
        let direct = simulate_excitation(&cfg, &exc).unwrap();
        assert_eq!(ds.data.u, direct.u);
        assert_eq!(ds.data.y, direct.theta_m);
        assert_eq!(ds.data.r.as_deref(), Some(&direct.theta_ref[..]));
        assert!((ds.data.ts - 5e-4).abs() < 1e-15);
        let back: SimConfig =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        assert_eq!(back, cfg);
        std::fs::remove_file(&csv).unwrap();
        std::fs::remove_file(&json).unwrap();
    }

    #[test]
    fn simulate_rejects_a_bad_effect_spec() {
        let cli = Cli::try_parse_from([
            "jointid",
            "simulate",
            "--out",
            temp("never.csv").to_str().unwrap(),
            "--effect",
            "backlash:widht=1",
        ])
        .unwrap();
        let loaders = default_loaders();
        let mut buf = Vec::new();
        let err = crate::cli::run(
            &cli,
            &mut Context {
                json: false,
                loaders: &loaders,
                out: &mut buf,
            },
        )
        .unwrap_err();
        assert!(err.to_string().contains("unknown key `widht`"), "{err}");
        assert!(!temp("never.csv").exists());
    }
}
