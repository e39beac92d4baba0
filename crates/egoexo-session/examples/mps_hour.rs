//! Writes a synthetic MPS device folder with an hour (or `SECONDS`) of 1 kHz closed-loop
//! trajectory — MPS's column set, a low-quality first 10 s, sample gaps from 1 µs to 1.2 ms —
//! streamed to disk, then imports it as the CLI does and prints rows per second.
//!
//! ```sh
//! cargo run --release -p egoexo-session --example mps_hour -- /tmp/mps_hour [SECONDS]
//! /usr/bin/time -v target/release/egoexo inspect /tmp/mps_hour   # peak memory of an import
//! ```

#[cfg(target_arch = "wasm32")]
fn main() {}

#[cfg(not(target_arch = "wasm32"))]
fn main() -> anyhow::Result<()> {
    use std::io::Write as _;
    use std::time::Instant;

    use egoexo_session::import::{ImportOptions, import_path};

    let mut args = std::env::args().skip(1);
    let dir = std::path::PathBuf::from(args.next().ok_or_else(|| anyhow::anyhow!("usage: mps_hour <dir> [seconds]"))?);
    let seconds: f64 = args.next().map_or(Ok(3600.0), |s| s.parse())?;
    std::fs::create_dir_all(dir.join("trajectory"))?;
    let path = dir.join("trajectory/closed_loop_trajectory.csv");
    let mut out = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(&path)?);
    writeln!(
        out,
        "graph_uid,tracking_timestamp_us,utc_timestamp_ns,tx_world_device,ty_world_device,tz_world_device,qx_world_device,qy_world_device,qz_world_device,qw_world_device,device_linear_velocity_x_device,device_linear_velocity_y_device,device_linear_velocity_z_device,angular_velocity_x_device,angular_velocity_y_device,angular_velocity_z_device,gravity_x_world,gravity_y_world,gravity_z_world,quality_score,geo_available,tx_ecef_device,ty_ecef_device,tz_ecef_device,qx_ecef_device,qy_ecef_device,qz_ecef_device,qw_ecef_device"
    )?;
    let (mut us, mut rows) = (1_000_000i64, 0u64);
    let end = us + (seconds * 1e6) as i64;
    while us <= end {
        let t = (us - 1_000_000) as f64 * 1e-6;
        // Walking a 3 m circle at head height, turning with it.
        let a = 0.25 * t;
        let (s, c) = ((a / 2.0).sin(), (a / 2.0).cos());
        let quality = if t < 10.0 { 0.2 } else { 0.95 };
        writeln!(
            out,
            "4d3c2b1a-0f9e-4d8c-b7a6-123456789abc,{us},{},{:.9},{:.9},{:.9},0.000000000,0.000000000,{s:.9},{c:.9},{:.6},{:.6},0.000000,0.000000,0.000000,0.250000,0.000000,0.000000,-9.810000,{quality:.6},0,,,,,,,",
            1_700_000_000_000_000_000i64 + us * 1000,
            3.0 * a.cos(),
            3.0 * a.sin(),
            1.62 + 0.02 * (11.0 * t).sin(),
            0.75 * (a.cos()),
            0.75 * (a.sin()),
        )?;
        rows += 1;
        us += match rows % 97 {
            13 => 1,
            51 => 1200,
            _ => 1000,
        };
    }
    out.flush()?;
    drop(out);
    let bytes = std::fs::metadata(&path)?.len();
    println!("wrote {rows} rows, {:.1} MB: {}", bytes as f64 / 1e6, path.display());
    let started = Instant::now();
    let file = std::io::BufReader::with_capacity(1 << 16, std::fs::File::open(&path)?);
    let read = egoexo_session::aria::trajectory::read_closed_loop_trajectory(
        "closed_loop_trajectory.csv",
        file,
        egoexo_session::aria::trajectory::Clock::Device,
        &mut |_| {},
    )?;
    let seconds = started.elapsed().as_secs_f64();
    println!(
        "the reader alone: {} rows in {seconds:.2} s: {:.2} M rows/s, {:.0} MB/s",
        read.poses.len(),
        rows as f64 / seconds / 1e6,
        bytes as f64 / seconds / 1e6
    );
    drop(read);
    let started = Instant::now();
    let imported = import_path(&dir, &ImportOptions::default())?;
    let seconds = started.elapsed().as_secs_f64();
    println!(
        "the whole import (read, convert, validate, floor): {} poses in {seconds:.2} s: {:.2} M rows/s, {:.0} MB/s",
        imported.session.wearer.head.len(),
        rows as f64 / seconds / 1e6,
        bytes as f64 / seconds / 1e6
    );
    for w in &imported.warnings {
        println!("  {w}");
    }
    Ok(())
}
