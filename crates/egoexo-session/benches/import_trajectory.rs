//! MPS closed-loop trajectory import, native: rows per second of
//! `read_closed_loop_trajectory` on 10 minutes of a 1 kHz trajectory (600 k rows, MPS's column
//! set), against the `csv` crate splitting the same bytes into fields without parsing them
//! (the in-run reference: the floor any CSV reader pays). Run with
//! `cargo bench -p egoexo-session`; an hour is 3.6 M rows (see `examples/mps_hour.rs` for the
//! whole-hour figure and its peak memory).

use std::fmt::Write as _;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use egoexo_session::aria::trajectory::{Clock, read_closed_loop_trajectory};

const ROWS: usize = 600_000;

fn trajectory_csv() -> String {
    let mut out = String::with_capacity(ROWS * 230);
    out.push_str("graph_uid,tracking_timestamp_us,utc_timestamp_ns,tx_world_device,ty_world_device,tz_world_device,qx_world_device,qy_world_device,qz_world_device,qw_world_device,device_linear_velocity_x_device,device_linear_velocity_y_device,device_linear_velocity_z_device,angular_velocity_x_device,angular_velocity_y_device,angular_velocity_z_device,gravity_x_world,gravity_y_world,gravity_z_world,quality_score,geo_available,tx_ecef_device,ty_ecef_device,tz_ecef_device,qx_ecef_device,qy_ecef_device,qz_ecef_device,qw_ecef_device\n");
    for i in 0..ROWS {
        let t = i as f64 * 1e-3;
        let a = 0.25 * t;
        let _ = writeln!(
            out,
            "4d3c2b1a-0f9e-4d8c-b7a6-123456789abc,{},-1,{:.9},{:.9},1.620000000,0.000000000,0.000000000,{:.9},{:.9},0.1,0.2,0.0,0.0,0.0,0.25,0.000000,0.000000,-9.810000,0.950000,0,,,,,,,",
            1_000_000 + i * 1000,
            3.0 * a.cos(),
            3.0 * a.sin(),
            (a / 2.0).sin(),
            (a / 2.0).cos()
        );
    }
    out
}

fn import(c: &mut Criterion) {
    let text = trajectory_csv();
    let mut group = c.benchmark_group("closed_loop_trajectory");
    group.sample_size(10);
    group.throughput(Throughput::Elements(ROWS as u64));
    group.bench_function("read (rows)", |b| {
        b.iter(|| {
            read_closed_loop_trajectory("t.csv", text.as_bytes(), Clock::Device, &mut |_| {}).unwrap().poses.len()
        })
    });
    group.bench_function("reference: csv fields only (rows)", |b| {
        b.iter(|| {
            let mut reader = csv::ReaderBuilder::new().from_reader(text.as_bytes());
            let mut record = csv::ByteRecord::new();
            let mut fields = 0usize;
            while reader.read_byte_record(&mut record).unwrap() {
                fields += record.len();
            }
            fields
        })
    });
    group.finish();
}

criterion_group!(benches, import);
criterion_main!(benches);
