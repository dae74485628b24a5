// SPDX-License-Identifier: MIT
// Benchmark (not a test): the time from connecting to the first fused frame in headless
// Chromium (WebGPU on SwiftShader), with the app's default settings, over N fresh browsers
// (no pipeline cache carried from one to the next) against one bridge replaying the sample:
// each run's time, the pipelines compiled by then and the page's start-up milestones, and the
// median. One number of `bench.mjs`, measured often enough to compare on a shared machine.
//
// usage: node tests/browser/first_frame.mjs [--webfusion target/release/webfusion] [--dist dist]
//          [--sample data/sample/fr1_rpy.wfr] [--repeat 5]
import { launchChromium, options, startBridge, waitFor } from './lib.mjs';

const { webfusion, dist, sample } = options({ out: 'out/first-frame' });
const repeatArg = process.argv.indexOf('--repeat');
const repeat = repeatArg > 0 ? Number(process.argv[repeatArg + 1]) : 5;
if (!(Number.isInteger(repeat) && repeat >= 1)) throw new Error(`--repeat needs a whole number >= 1, got ${process.argv[repeatArg + 1]}`);

const bridge = await startBridge(webfusion, sample, dist, '127.0.0.1:0');
const times = [];
try {
  for (let i = 0; i < repeat; i++) {
    const browser = await launchChromium();
    try {
      const page = await browser.newPage({ viewport: { width: 1400, height: 1000 } });
      await page.goto(`http://${bridge.addr}/?autoplay=1`);
      const first = await waitFor(page, 'the first frame', (s) => s.frames_done >= 1 && s.time_to_first_frame_ms != null, 300_000);
      times.push(first.time_to_first_frame_ms);
      console.log(`run ${i + 1}/${repeat}: first fused frame ${first.time_to_first_frame_ms.toFixed(0)} ms after connecting; pipelines compiled by then ${JSON.stringify(first.first_frame_kernels)}; milestones (ms after start) ${JSON.stringify(first.startup_ms)}`);
    } finally {
      await browser.close();
    }
  }
} finally {
  bridge.child.kill('SIGKILL');
}
const sorted = [...times].sort((a, b) => a - b);
const median = sorted.length % 2 ? sorted[(sorted.length - 1) / 2] : (sorted[sorted.length / 2 - 1] + sorted[sorted.length / 2]) / 2;
console.log(`time to the first fused frame: median ${median.toFixed(0)} ms after connecting (min ${sorted[0].toFixed(0)}, max ${sorted[sorted.length - 1].toFixed(0)}, ${times.length} runs)`);
