// SPDX-License-Identifier: MIT
// Benchmark (not a test): seed 000's virtual Kinect at 640x480, exact and with the Kinect noise
// model, on the same map and poses three ways, printed side by side:
//   native   `webfusion simulate --bench` (Vulkan: lavapipe or a GPU; render + readback);
//   served   `webfusion serve --map` answering `scripts/render_client.py` (the round trip a
//            planner sees: request, render, RVL+DEFLATE, WebSocket, decode);
//   browser  the page's virtual sensor in headless Chromium (WebGPU: SwiftShader), the map
//            opened from the bridge; the page's own submission-to-readback time.
// Thesis 000: 16.1 ms per frame on a GTX 680, 412 ms on its CPU; the goal <= 30 ms on
// lavapipe.
//
// usage: node tests/browser/bench_sim.mjs [--webfusion target/release/webfusion] [--dist dist]
//          [--sample data/sample/fr1_rpy.wfr] [--map M.wfm] [--poses TUM.txt] [--views 32]
//          [--out out/bench-sim]
// Without --map the sample is fused first (`reconstruct --save-map`, default settings) and its
// trajectory gives the poses.
import { spawnSync } from 'node:child_process';
import { mkdirSync, readFileSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { launchChromium, options, startBridge, waitFor } from './lib.mjs';

const { webfusion, dist, sample, out } = options({ out: 'out/bench-sim' });
const arg = (name) => { const i = process.argv.indexOf(name); return i > 0 ? process.argv[i + 1] : undefined; };
const views = Number(arg('--views') ?? 32);
if (!(Number.isInteger(views) && views >= 2)) throw new Error(`--views needs a whole number >= 2, got ${arg('--views')}`);
mkdirSync(out, { recursive: true });
const median = (values) => [...values].sort((x, y) => x - y)[Math.floor(values.length / 2)];
const run = (args) => {
  const r = spawnSync(webfusion, args, { encoding: 'utf8' });
  if (r.status !== 0) throw new Error(`webfusion ${args[0]} failed: ${r.stderr}`);
  return r.stdout;
};

let mapPath = arg('--map');
let posesPath = arg('--poses');
if (!mapPath) {
  mapPath = join(out, 'map.wfm');
  console.log(`fusing ${sample} into ${mapPath} ...`);
  run(['reconstruct', sample, '--out', join(out, 'fused'), '--no-mesh', '--save-map', mapPath]);
  posesPath ??= join(out, 'fused', 'trajectory.txt');
}
if (!posesPath) throw new Error('--map needs --poses (a TUM trajectory in the map\'s frame)');
const lines = readFileSync(posesPath, 'utf8').split('\n').filter((l) => l.trim() && !l.startsWith('#'));
// `views` poses spread over the trajectory.
const chosen = Array.from({ length: views }, (_, i) => lines[Math.floor((i * lines.length) / views)]);
const viewsPath = join(out, 'views.txt');
writeFileSync(viewsPath, chosen.join('\n') + '\n');

// Native.
const native = {};
let mapLine = '';
for (const [name, extra] of [['exact', []], ['noise', ['--noise', 'kinect', '--seed', '1']]]) {
  const text = run(['simulate', '--map', mapPath, '--poses', viewsPath, '--bench', ...extra]);
  mapLine = text.split('\n')[0];
  const m = text.match(/median ([\d.]+) ms, p95 ([\d.]+) ms/);
  if (!m) throw new Error(`no timing in simulate's output: ${text}`);
  native[name] = { median: Number(m[1]), p95: Number(m[2]) };
}

// Served, and the browser, against one bridge.
const bridge = await startBridge(webfusion, sample, dist, '127.0.0.1:0', ['--map', mapPath]);
const served = {};
const browserMs = {};
let adapter = '', mapMiB = 0;
try {
  for (const [name, extra] of [['exact', []], ['noise', ['--noise', 'kinect', '--seed', '1']]]) {
    const r = spawnSync('python3', ['scripts/render_client.py', `ws://${bridge.addr}/ws`, '--poses', viewsPath, ...extra], { encoding: 'utf8' });
    if (r.status !== 0) throw new Error(`render_client.py failed: ${r.stderr}`);
    const trips = r.stdout.trim().split('\n').map((l) => JSON.parse(l).round_trip_ms);
    // The first request also builds the server's sensor.
    served[name] = { median: median(trips.slice(1)), first: trips[0] };
  }
  const browser = await launchChromium();
  try {
    const page = await browser.newPage({ viewport: { width: 1400, height: 1000 } });
    await page.goto(`http://${bridge.addr}/`);
    await waitFor(page, 'the link', (s) => s.link === 'connected', 120_000);
    await page.click('#map-from-bridge');
    const opened = await waitFor(page, 'the opened map', (s) => s.sensor?.map, 300_000);
    adapter = opened.adapter;
    mapMiB = opened.sensor.map.memory_bytes / 1048576;
    let rendered = 0;
    for (const name of ['exact', 'noise']) {
      if (name === 'noise') {
        await page.check('#sim-noise');
        rendered++;
        await page.waitForFunction((n) => window.webfusion.status.sensor.rendered >= n, rendered, { polling: 10, timeout: 300_000 });
      }
      const ms = [];
      for (const line of chosen) {
        await page.fill('#sim-pose', line.split(/\s+/).slice(1, 8).join(' '));
        const t = Date.now();
        await page.click('#sim-render');
        rendered++;
        await page.waitForFunction((n) => window.webfusion.status.sensor.rendered >= n, rendered, { polling: 10, timeout: 300_000 });
        ms.push(Date.now() - t);
      }
      const s = await page.evaluate(() => window.webfusion.status);
      if (s.message) throw new Error(`the page reported: ${s.message}`);
      // The page's own figure: median over its last 32 renders (all of this mode when views >= 32).
      browserMs[name] = { page: s.sensor.median_ms, click: median(ms) };
    }
  } finally {
    await browser.close();
  }
} finally {
  bridge.child.kill('SIGKILL');
}

const row = (name, ...cells) => console.log(name.padEnd(34) + cells.map((c) => String(c).padStart(14)).join(''));
console.log(`\n${views} views at 640x480 along ${posesPath}; ${mapLine}`);
console.log(`browser: ${adapter}; the map in the page: ${mapMiB.toFixed(1)} MiB on the GPU\n`);
row('ms per frame (median)', 'exact', 'Kinect noise', 'noise/exact');
for (const [name, e, n] of [
  ['native simulate (render+readback)', native.exact.median, native.noise.median],
  ['served, Python client round trip', served.exact.median, served.noise.median],
  ['browser, submission to readback', browserMs.exact.page, browserMs.noise.page],
  ['browser, click to status', browserMs.exact.click, browserMs.noise.click],
]) row(name, e.toFixed(1), n.toFixed(1), (n / e).toFixed(2));
console.log(`\nnative p95: exact ${native.exact.p95.toFixed(1)} ms, noise ${native.noise.p95.toFixed(1)} ms; served first request (builds the sensor): ${served.exact.first.toFixed(0)} ms`);
console.log(`served / native: ${(served.exact.median / native.exact.median).toFixed(2)}x; browser / native: ${(browserMs.exact.page / native.exact.median).toFixed(2)}x`);
console.log(`goal: <= 30 ms per frame on lavapipe (thesis 000: 16.1 ms GTX 680, 412 ms CPU): native exact ${(native.exact.median / 30).toFixed(1)}x the goal`);
