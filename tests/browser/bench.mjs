// SPDX-License-Identifier: MIT
// Benchmark (not a test): the same KinectFusion pipeline on the same frames, natively
// (`webfusion reconstruct`, Vulkan: lavapipe or a GPU) and in headless Chromium (WebGPU:
// SwiftShader), printed side by side as per-stage medians and frames/s, plus the wasm size
// (gzip) and the time from page load to the first fused frame.
//
// usage: node tests/browser/bench.mjs [--webfusion target/release/webfusion] [--dist dist]
//          [--sample data/sample/fr1_rpy.wfr] [--volume 256] [--voxel-mm 20] [--out out/bench-web]
//          [--repeat N] [--planes 0|1]
// The page runs what native `reconstruct` runs (feature odometry on, as there): seed 003's
// per-frame plane segmentation, which `reconstruct` does not do, is off unless `--planes 1`
// (the page's own default) measures the page as it opens.
// With --repeat N the native and browser runs alternate N times and the frames/s ratio and the
// time to the first frame are reported per run and as medians: on a shared machine one run's
// speed can differ from the next by half, and only runs side by side compare.
import { spawnSync } from 'node:child_process';
import { readFileSync, readdirSync } from 'node:fs';
import { join } from 'node:path';
import { gzipSync } from 'node:zlib';
import { launchChromium, options, startBridge, waitFor } from './lib.mjs';

const { webfusion, dist, sample, out, map, volume, voxelMm, planes } = options({ out: 'out/bench-web', map: 'sparse', volume: 256, 'voxel-mm': 20, planes: '0' });
if (!['0', '1'].includes(planes)) throw new Error(`--planes takes 0 or 1, got ${planes}`);
const repeatArg = process.argv.indexOf('--repeat');
const repeat = repeatArg > 0 ? Number(process.argv[repeatArg + 1]) : 1;
if (!(Number.isInteger(repeat) && repeat >= 1)) throw new Error(`--repeat needs a whole number >= 1, got ${process.argv[repeatArg + 1]}`);

const wasm = readdirSync(dist).filter((f) => f.endsWith('.wasm')).map((f) => join(dist, f));
if (wasm.length !== 1) throw new Error(`expected one .wasm in ${dist}, found ${wasm.length}`);
const wasmBytes = readFileSync(wasm[0]);

/** One native run, then one browser run, on the same frames and settings. */
async function runOnce() {
  const t0 = Date.now();
  const native = spawnSync(webfusion, ['reconstruct', sample, '--out', join(out, 'native'), '--map-kind', map, '--volume', String(volume), '--voxel-size', String(voxelMm / 1000), '--centred', '--no-mesh'], { encoding: 'utf8' });
  if (native.status !== 0) throw new Error(`webfusion reconstruct failed: ${native.stderr}`);
  const nativeWallS = (Date.now() - t0) / 1000;
  const stats = JSON.parse(readFileSync(join(out, 'native', 'stats.json'), 'utf8'));

  const bridge = await startBridge(webfusion, sample, dist, '127.0.0.1:0');
  const browser = await launchChromium();
  let done, firstMs, browserWallS;
  try {
    const page = await browser.newPage({ viewport: { width: 1400, height: 1000 } });
    const tLoad = Date.now();
    await page.goto(`http://${bridge.addr}/?map=${map}&volume=${volume}&voxel_mm=${voxelMm}&centred=1&planes=${planes}&autoplay=1`);
    const first = await waitFor(page, 'the first frame', (s) => s.frames_done >= 1, 300_000);
    firstMs = Date.now() - tLoad;
    const tFirst = Date.now();
    done = await waitFor(page, 'every frame', (s) => s.frames_done >= first.frames_total && s.state === 'ended', 3_600_000);
    browserWallS = (Date.now() - tFirst) / 1000;
  } finally {
    await browser.close();
    bridge.child.kill('SIGKILL');
  }
  return { stats, nativeWallS, done, firstMs, browserWallS };
}

const runs = [];
for (let i = 0; i < repeat; i++) {
  const run = await runOnce();
  run.ratio = ((run.done.frames_done - 1) / run.browserWallS) / (run.stats.frames / run.nativeWallS);
  runs.push(run);
  if (repeat > 1) console.log(`run ${i + 1}/${repeat}: browser/native frames/s ${run.ratio.toFixed(3)}; first fused frame ${run.firstMs} ms after load, ${run.done.time_to_first_frame_ms?.toFixed(0)} ms after connecting`);
}
const median = (values) => [...values].sort((x, y) => x - y)[Math.floor(values.length / 2)];
const { stats, nativeWallS, done, firstMs, browserWallS } = runs[runs.length - 1];
const frames = stats.frames;
const row = (name, nat, web) => console.log(`${name.padEnd(28)}${nat.padStart(14)}${web.padStart(16)}${(typeof nat === 'string' && nat.endsWith('ms') && web.endsWith('ms') ? `${(parseFloat(web) / parseFloat(nat)).toFixed(2)}x`.padStart(10) : '')}`);
console.log(`\n${frames} frames of ${sample}, ${volume}^3 voxels of ${voxelMm} mm; the page's plane segmentation ${planes === '1' ? 'on' : 'off (as native reconstruct)'}`);
console.log(`native: ${stats.adapter}\nbrowser: ${done.adapter}\n`);
row('', 'native', 'browser');
// stats.json names GPU-timed stages `gpu <stage>` (wall clock where the adapter has no timestamps).
const med = (stage) => (stats.stages_ms[`gpu ${stage}`] ?? stats.stages_ms[stage])?.median;
for (const [nativeStage, webStage] of [['preprocess', 'preprocess'], ['features', 'features'], ['track', 'track'], ['integrate', 'integrate'], ['raycast', 'raycast']]) {
  row(`${webStage} (median)`, `${med(nativeStage)?.toFixed(1)} ms`, `${done.stages_ms[webStage].toFixed(1)} ms`);
}
// Both sides' frame: the GPU stages (native: the frame's first to last timestamp).
row('frame (median)', `${med('frame')?.toFixed(1)} ms`, `${(done.stages_ms.preprocess + done.stages_ms.features + done.stages_ms.track + done.stages_ms.integrate + done.stages_ms.raycast).toFixed(1)} ms`);
row('decode + views (browser)', '-', `${(done.stages_ms.decode + done.stages_ms.views).toFixed(1)} ms`);
const [nativeFps, browserFps] = [frames / nativeWallS, (done.frames_done - 1) / browserWallS];
row('frames/s (whole run)', nativeFps.toFixed(2), browserFps.toFixed(2));
console.log(`browser / native frames/s: ${(browserFps / nativeFps).toFixed(2)}${repeat > 1 ? ` (this run); median of ${repeat} runs ${median(runs.map((r) => r.ratio)).toFixed(2)}, first frame median ${median(runs.map((r) => r.done.time_to_first_frame_ms ?? NaN)).toFixed(0)} ms after connecting` : ''}`);
console.log(`\nwasm: ${(wasmBytes.length / 1024).toFixed(0)} KiB, ${(gzipSync(wasmBytes, { level: 9 }).length / 1024).toFixed(0)} KiB gzip (${wasm[0]})`);
console.log(`time to first fused frame: ${firstMs} ms from page load (${done.time_to_first_frame_ms?.toFixed(0)} ms from connecting; pipelines compiled by then, of all: ${JSON.stringify(done.first_frame_kernels)}); milestones (ms after start) ${JSON.stringify(done.startup_ms)}`);
console.log(`host per frame (last frame's pipeline): ${JSON.stringify(done.host_per_frame)}`);
console.log(`native wall time includes start-up and reading; browser frames/s counts from the first frame. ATE vs ground truth: native ${stats.ate ? (stats.ate.rmse_m * 100).toFixed(2) + ' cm' : 'n/a'}, browser ${done.ate_rmse_m === null ? 'n/a' : (done.ate_rmse_m * 100).toFixed(2) + ' cm'}`);
