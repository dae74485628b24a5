// SPDX-License-Identifier: MIT
// Measurement (not a test): a room-sized run in the browser. Serves a recording (made by
// `webfusion synth-room`) to the web app in headless Chromium (WebGPU: SwiftShader), fuses every
// frame into the default sparse map at the given voxel size, and prints what the page reports:
// frames, lost frames, ATE against the recording's ground truth, blocks on the GPU and swapped
// out to wasm memory, and frames/s.
//
// usage: node tests/browser/room.mjs --sample out/room/room.wfr [--voxel-mm 10]
//          [--webfusion target/release/webfusion] [--dist dist]
import { launchChromium, options, startBridge, waitFor } from './lib.mjs';

const { webfusion, dist, sample, voxelMm } = options({ out: 'out/room', 'voxel-mm': 10 });
const bridge = await startBridge(webfusion, sample, dist, '127.0.0.1:0');
const browser = await launchChromium();
try {
  const page = await browser.newPage({ viewport: { width: 1400, height: 1000 } });
  await page.goto(`http://${bridge.addr}/?voxel_mm=${voxelMm}&autoplay=1`);
  const first = await waitFor(page, 'the first frame', (s) => s.frames_done >= 1, 600_000);
  const t0 = Date.now();
  let peakHost = 0;
  const done = await waitFor(page, 'every frame', (s) => {
    peakHost = Math.max(peakHost, s.volume?.blocks_on_host ?? 0);
    return s.frames_done >= first.frames_total && s.state === 'ended';
  }, 6 * 3_600_000);
  const seconds = (Date.now() - t0) / 1000;
  const v = done.volume;
  console.log(`browser (${done.adapter}): ${done.frames_done} frames of ${sample} at ${voxelMm} mm voxels, ${done.lost_frames} lost, ATE ${done.ate_rmse_m === null ? '-' : (100 * done.ate_rmse_m).toFixed(2) + ' cm'}`);
  console.log(`map: ${v.kind}, ${v.blocks_used} of ${v.pool_blocks} blocks on the GPU (${(v.memory_bytes / 1048576).toFixed(0)} MiB), ${v.blocks_on_host} on the host at the end (${(v.host_bytes / 1048576).toFixed(1)} MiB of wasm memory; peak ${peakHost} blocks), full: ${v.full}`);
  console.log(`${((done.frames_done - 1) / seconds).toFixed(2)} frames/s after the first; stage medians ${JSON.stringify(done.stages_ms)}`);
} finally {
  await browser.close();
  bridge.child.kill('SIGKILL');
}
