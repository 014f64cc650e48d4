//! `actrack-cli calibrate --image FRAME --corners "u,v u,v u,v u,v" --table-size W,D
//! --hfov DEG --shoulder u,v --shoulder-height H -o scene.toml [--preview preview.png]`.

use std::path::PathBuf;
use std::process::ExitCode;

use actrack::calibrate::{
    CalibrationInput, Intrinsics, ShoulderHeight, calibrate, draw_preview, load_corners,
    parse_corners, rest_pose,
};
use actrack::model::ActionModel;
use actrack::scene::{EdgeSettings, Side};

/// Options of `calibrate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// One frame of the video (PNG/JPEG), or any image from the same camera position; sets the
    /// image size and is the background of the preview.
    #[arg(long)]
    pub image: PathBuf,
    /// The table's four corners in pixels, in the order near-left, near-right, far-right,
    /// far-left as the actor sees them: "u,v u,v u,v u,v".
    #[arg(long, conflicts_with = "corners_file", allow_hyphen_values = true)]
    pub corners: Option<String>,
    /// The corners from a file: JSON `[[u, v], …]` (or `{"corners": …}`) or CSV `u,v` lines.
    #[arg(long)]
    pub corners_file: Option<PathBuf>,
    /// The table's size in metres: along its near edge, then across it ("1.2,0.8").
    #[arg(long)]
    pub table_size: String,
    /// The size of the region where the targets lie, centred on the table, in metres ("0.6,0.3";
    /// default: the whole table).
    #[arg(long)]
    pub region: Option<String>,
    /// Height of the table surface above the floor in metres.
    #[arg(long, default_value_t = 0.75)]
    pub table_height: f64,
    /// Intrinsics from an OpenCV calibration (cv::FileStorage YAML or JSON with camera_matrix
    /// and dist_coeffs).
    #[arg(long, conflicts_with_all = ["hfov", "focal_px"])]
    pub intrinsics: Option<PathBuf>,
    /// Horizontal field of view in degrees (square pixels, centred principal point, no
    /// distortion).
    #[arg(long, conflicts_with = "focal_px")]
    pub hfov: Option<f64>,
    /// Focal length in pixels (square pixels, centred principal point, no distortion).
    #[arg(long)]
    pub focal_px: Option<f64>,
    /// The acting arm: right or left.
    #[arg(long, default_value = "right")]
    pub arm: String,
    /// The acting shoulder's pixel "u,v" in a frame where the arm rests.
    #[arg(long)]
    pub shoulder: String,
    /// The shoulder's height above the table surface in metres.
    #[arg(long, conflicts_with = "person_height")]
    pub shoulder_height: Option<f64>,
    /// Or the person's height in metres (the shoulder height follows from body proportions;
    /// seated unless --standing).
    #[arg(long)]
    pub person_height: Option<f64>,
    /// With --person-height: the person stands at the table.
    #[arg(long)]
    pub standing: bool,
    /// Reject the calibration when a corner reprojects further than this, pixels.
    #[arg(long, default_value_t = 5.0)]
    pub max_error: f64,
    /// Edge threshold τ written into the scene's `[edges]` table (SPEC §4.1; lower for low contrast).
    #[arg(long, default_value_t = 0.2)]
    pub tau: f64,
    /// The model whose rest pose the preview draws (default: the shipped default model).
    #[arg(long, short = 'm')]
    pub model: Option<PathBuf>,
    /// The scene file to write.
    #[arg(long, short = 'o')]
    pub output: PathBuf,
    /// The preview image to write (table outline, axes, corners, the arm at rest).
    #[arg(long)]
    pub preview: Option<PathBuf>,
}

fn pair(s: &str, what: &str) -> Result<[f64; 2], super::UsageError> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| super::UsageError(format!("{what} `{s}`: expected two numbers a,b")))?;
    match v[..] {
        [a, b] if a.is_finite() && b.is_finite() => Ok([a, b]),
        _ => Err(super::UsageError(format!(
            "{what} `{s}`: expected two numbers a,b"
        ))),
    }
}

/// Runs `calibrate`.
pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let usage = |m: String| -> anyhow::Error { super::UsageError(m).into() };
    let img = image::open(&args.image)
        .map_err(|e| {
            usage(format!(
                "{}: cannot read the image: {e}",
                args.image.display()
            ))
        })?
        .to_rgb8();
    let (width, height) = img.dimensions();
    let corners = match (&args.corners, &args.corners_file) {
        (Some(s), None) => parse_corners(s).map_err(|e| usage(format!("--corners: {e}")))?,
        (None, Some(p)) => load_corners(p)?,
        _ => {
            return Err(usage(
                "give the corners: --corners or --corners-file".into(),
            ));
        }
    };
    let intrinsics = match (&args.intrinsics, args.hfov, args.focal_px) {
        (Some(p), None, None) => Intrinsics::load(p)?.for_size(width, height)?,
        (None, Some(h), None) => Intrinsics::from_hfov(width, height, h)?,
        (None, None, Some(f)) => Intrinsics::from_focal(width, height, f)?,
        _ => {
            return Err(usage(
                "give the camera: --intrinsics FILE, --hfov DEGREES or --focal-px PIXELS".into(),
            ));
        }
    };
    let side = match args.arm.as_str() {
        "right" => Side::Right,
        "left" => Side::Left,
        other => return Err(usage(format!("--arm {other}: expected right or left"))),
    };
    let shoulder_height = match (args.shoulder_height, args.person_height) {
        (Some(h), None) => ShoulderHeight::AboveTable(h),
        (None, Some(h)) => ShoulderHeight::PersonHeight {
            height: h,
            standing: args.standing,
        },
        _ => {
            return Err(usage(
                "give the shoulder's height: --shoulder-height METRES (above the table) or \
                 --person-height METRES"
                    .into(),
            ));
        }
    };
    if !(args.tau.is_finite() && args.tau > 0.0 && args.tau <= 1.0) {
        return Err(usage(format!("--tau {}: must be in (0, 1]", args.tau)));
    }
    let input = CalibrationInput {
        width,
        height,
        intrinsics,
        corners: corners.clone(),
        table_size: pair(&args.table_size, "--table-size")?,
        region_size: args
            .region
            .as_deref()
            .map(|r| pair(r, "--region"))
            .transpose()?,
        table_height: args.table_height,
        side,
        shoulder_px: pair(&args.shoulder, "--shoulder")?,
        shoulder_height,
        max_error_px: args.max_error,
        edges: EdgeSettings {
            tau: args.tau,
            ..EdgeSettings::default()
        },
    };
    let cal = calibrate(&input)?;
    let e = cal.corner_errors_px;
    println!(
        "corner reprojection error: rms {:.2} px, max {:.2} px (corners: {:.2} {:.2} {:.2} {:.2} px)",
        cal.rms_error_px,
        cal.max_error_px(),
        e[0],
        e[1],
        e[2],
        e[3]
    );
    let cam = &cal.scene.cameras[0];
    let c = cam.centre();
    println!(
        "camera: {:.2} m above the table, {:.2} m from its centre; shoulder {:.2} m above the table at ({:.2}, {:.2}) m",
        c.z - args.table_height,
        (c - cal.scene.table.placement.origin).norm(),
        cal.shoulder_above_table,
        cal.scene.actor.origin.x,
        cal.scene.actor.origin.y,
    );
    std::fs::write(&args.output, cal.scene.to_toml_string())
        .map_err(|e| actrack::Error::write(&args.output, e))?;
    println!("scene: {}", args.output.display());
    if let Some(p) = &args.preview {
        let model = match &args.model {
            Some(m) => ActionModel::load(m)?,
            None => actrack::model::default_model()?,
        };
        let lengths = [model.arm_lengths.upper_arm, model.arm_lengths.forearm_hand];
        let rest = rest_pose(Some(&model), cal.shoulder_above_table);
        let mut out = img;
        draw_preview(&mut out, &cal, &corners, &rest, lengths);
        out.save(p)
            .map_err(|e| actrack::Error::write(p, std::io::Error::other(e.to_string())))?;
        println!("preview: {}", p.display());
    }
    Ok(ExitCode::SUCCESS)
}
