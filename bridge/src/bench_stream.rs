// SPDX-License-Identifier: MIT
//! Streaming benchmarks (not tests: timings on shared machines are noisy).
//!
//! - `bench-codecs`: depth compression per 640x480 frame: RVL and RVL+DEFLATE (ours) against
//!   16-bit PNG (the `png` crate) and zstd levels 1 and 3 on the raw bytes, all on the same
//!   frames in the same run; encode/decode median ms and compression ratio, each checked lossless.
//! - `bench-clients`: sustained frames/s from a `webfusion serve` child process to 1, 4 and 16
//!   WebSocket clients on loopback, with the server's CPU use and resident memory.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use futures_util::{SinkExt as _, StreamExt as _};
use webfusion_core::DepthImage;
use webfusion_core::codec::{png, rvl};
use webfusion_core::protocol::{Control, Message};

use crate::calib::CalibrationArgs;
use crate::timing::summarize;

#[derive(clap::Args)]
pub(crate) struct BenchCodecsArgs {
    /// TUM RGB-D directory or `.wfr` recording.
    #[arg(long, default_value = crate::DEFAULT_SAMPLE)]
    source: PathBuf,
    /// Frames to use (from the first).
    #[arg(long, default_value_t = 30)]
    frames: usize,
    #[command(flatten)]
    calibration: CalibrationArgs,
}

#[derive(clap::Args)]
pub(crate) struct BenchClientsArgs {
    /// Source to serve.
    #[arg(long, default_value = crate::DEFAULT_SAMPLE)]
    source: PathBuf,
    /// Client counts to measure, comma-separated.
    #[arg(long, default_value = "1,4,16")]
    clients: String,
    /// Seconds of streaming per client count.
    #[arg(long, default_value_t = 5.0)]
    seconds: f64,
}

type Encode = fn(&DepthImage) -> Vec<u8>;
type Decode = fn(&[u8], u32, u32) -> anyhow::Result<Vec<u16>>;

fn zstd_encode(image: &DepthImage, level: i32) -> Vec<u8> {
    let raw: Vec<u8> = image.units.iter().flat_map(|u| u.to_le_bytes()).collect();
    zstd::bulk::compress(&raw, level).unwrap_or_default()
}

fn zstd_decode(bytes: &[u8], w: u32, h: u32) -> anyhow::Result<Vec<u16>> {
    let raw = zstd::bulk::decompress(bytes, 2 * (w * h) as usize)?;
    Ok(raw.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect())
}

pub(crate) fn bench_codecs(args: &BenchCodecsArgs) -> anyhow::Result<()> {
    let mut source = crate::open(&args.source, &args.calibration)?;
    let count = args.frames.min(source.frame_count());
    anyhow::ensure!(count > 0, "no frames to measure");
    let depths: Vec<DepthImage> = (0..count).map(|i| source.read_frame(i).map(|f| f.depth)).collect::<Result<_, _>>()?;
    let (w, h) = (depths[0].width_px, depths[0].height_px);
    let raw_bytes = 2.0 * f64::from(w * h);
    let codecs: [(&str, Encode, Decode); 6] = [
        ("rvl", |d| rvl::rvl_encode(&d.units), |b, w, h| Ok(rvl::rvl_decode(b, (w * h) as usize)?)),
        ("rvl+deflate", |d| rvl::rvl_deflate_encode(&d.units), |b, w, h| Ok(rvl::rvl_deflate_decode(b, (w * h) as usize)?)),
        ("png-16 (png crate)", |d| png::encode_depth16(d).unwrap_or_default(), |b, w, h| Ok(png::decode_depth16(b, w, h)?.units)),
        ("zstd-1 (raw u16)", |d| zstd_encode(d, 1), zstd_decode),
        ("zstd-3 (raw u16)", |d| zstd_encode(d, 3), zstd_decode),
        ("zstd-9 (raw u16)", |d| zstd_encode(d, 9), zstd_decode),
    ];
    println!("depth codecs on {count} frames of {} ({w}x{h}), median per frame:", source.name());
    println!("{:<20} {:>10} {:>10} {:>10} {:>8} {:>14}", "codec", "encode ms", "decode ms", "KiB", "ratio", "vs rvl (enc+dec)");
    let mut rvl_total_ms = None;
    for (name, encode, decode) in codecs {
        let (mut enc_ms, mut dec_ms, mut sizes) = (Vec::new(), Vec::new(), Vec::new());
        for depth in &depths {
            let t = Instant::now();
            let bytes = encode(depth);
            enc_ms.push(t.elapsed().as_secs_f64() * 1e3);
            let t = Instant::now();
            let units = decode(&bytes, w, h).with_context(|| format!("{name} decode"))?;
            dec_ms.push(t.elapsed().as_secs_f64() * 1e3);
            anyhow::ensure!(units == depth.units, "{name} is not lossless");
            sizes.push(bytes.len() as f64);
        }
        let median = |samples: &[f64]| summarize(samples).median_ms;
        let (enc, dec, size) = (median(&enc_ms), median(&dec_ms), median(&sizes));
        let total = enc + dec;
        let base = *rvl_total_ms.get_or_insert(total);
        println!("{name:<20} {enc:>10.2} {dec:>10.2} {:>10.1} {:>8.2} {:>13.2}x", size / 1024.0, raw_bytes / size, total / base);
    }
    Ok(())
}

/// CPU seconds (user + system) and resident KiB of a process, from /proc.
fn process_usage(pid: u32) -> Option<(f64, u64)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let rss_kib = status.lines().find(|l| l.starts_with("VmRSS:"))?.split_whitespace().nth(1)?.parse().ok()?;
    Some((ticks / 100.0, rss_kib))
}

pub(crate) fn bench_clients(args: &BenchClientsArgs) -> anyhow::Result<()> {
    let counts: Vec<usize> = args.clients.split(',').map(|s| s.trim().parse().with_context(|| format!("--clients {s:?}"))).collect::<anyhow::Result<_>>()?;
    let exe = std::env::current_exe()?;
    let mut child = std::process::Command::new(exe)
        .args(["serve", "--bind", "127.0.0.1:0", "--source"])
        .arg(&args.source)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .context("starting webfusion serve")?;
    let stdout = child.stdout.take().context("server stdout")?;
    let mut line = String::new();
    std::io::BufRead::read_line(&mut std::io::BufReader::new(stdout), &mut line)?;
    let addr = line.split("http://").nth(1).and_then(|r| r.split('/').next()).with_context(|| format!("no URL in {line:?}"))?.to_owned();
    let pid = child.id();
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    println!("sustained lossless replay (rate 0 = as fast as each client reads, looping) from {} over loopback:", args.source.display());
    println!("{:>8} {:>14} {:>14} {:>12} {:>14} {:>12}", "clients", "frames/s each", "frames/s all", "MiB/s all", "server CPU %", "server MiB");
    let result = runtime.block_on(async {
        for &clients in &counts {
            let before = process_usage(pid);
            let start = Instant::now();
            let deadline = Duration::from_secs_f64(args.seconds);
            let tasks: Vec<_> = (0..clients)
                .map(|_| {
                    let url = format!("ws://{addr}/ws");
                    tokio::spawn(async move {
                        let (mut socket, _) = tokio_tungstenite::connect_async(url).await?;
                        for control in [Control::Rate(0.0), Control::Loop(true), Control::Play] {
                            socket.send(Message::Control(control).encode().into()).await?;
                        }
                        let (mut frames, mut bytes) = (0_u64, 0_u64);
                        let begun = Instant::now();
                        while begun.elapsed() < deadline {
                            match tokio::time::timeout(Duration::from_secs(10), socket.next()).await {
                                Ok(Some(Ok(tokio_tungstenite::tungstenite::Message::Binary(b)))) => {
                                    bytes += b.len() as u64;
                                    if matches!(Message::decode(&b), Ok(Message::Frame(_))) {
                                        frames += 1;
                                    }
                                }
                                Ok(Some(Ok(_))) => {}
                                _ => break,
                            }
                        }
                        socket.close(None).await.ok();
                        anyhow::Ok((frames, bytes, begun.elapsed().as_secs_f64()))
                    })
                })
                .collect();
            let mut per_client = Vec::new();
            let mut total_bytes = 0;
            for task in tasks {
                let (frames, bytes, seconds) = task.await??;
                per_client.push(frames as f64 / seconds);
                total_bytes += bytes;
            }
            let wall = start.elapsed().as_secs_f64();
            let after = process_usage(pid);
            let (cpu, rss) = match (before, after) {
                (Some((c0, _)), Some((c1, rss))) => (format!("{:.0}", 100.0 * (c1 - c0) / wall), format!("{:.1}", rss as f64 / 1024.0)),
                _ => ("n/a".to_owned(), "n/a".to_owned()),
            };
            let all: f64 = per_client.iter().sum();
            let min = per_client.iter().copied().fold(f64::INFINITY, f64::min);
            println!("{clients:>8} {:>14} {all:>14.1} {:>12.1} {cpu:>14} {rss:>12}", format!("{:.1} (min {min:.1})", all / clients as f64), total_bytes as f64 / wall / (1 << 20) as f64);
        }
        anyhow::Ok(())
    });
    let _ = child.kill();
    let _ = child.wait();
    result
}
