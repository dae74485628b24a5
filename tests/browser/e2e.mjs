// SPDX-License-Identifier: MIT
// End-to-end test of the web app in real headless Chromium on WebGPU (SwiftShader):
//   1. the native `webfusion reconstruct` fuses the bundled sample (the reference trajectory);
//   2. `webfusion serve` serves the built app (dist/) and the sample's frames;
//   3. the page connects, fuses every frame on WebGPU; midway the bridge is killed and started
//      again on the same port, and the page must carry on by itself (no reload);
//   4. the browser's trajectory must match the native one (same world frame, so no alignment:
//      RMSE < 5 mm, max < 10 mm), and a screenshot of the free 3D view must
//      show a model (decoded PNG pixels, not just a file);
//   5. the mesh and trajectory exports arrive as downloads with the right contents;
//   6. a second page opened with unparsable settings in its URL (?voxel_mm=abc&rate=NaN) falls
//      back to the defaults with a visible message and fuses; its GPU device is then destroyed
//      (as a driver reset would) and the page must rebuild the pipeline and carry on fusing;
//   7. the virtual sensor (seed 000): in the fused map at the last frame's pose, beside the real
//      frame with seed 000's metrics, exact and with Kinect noise, downloaded as a 16-bit PNG;
//      then the native run's saved map, offered by `serve --map`, opened in a fresh page without
//      fusing, shown in the free view, and rendered at a pose of the native trajectory as
//      `webfusion simulate` renders it there; then again in a page whose map memory
//      (?map_mib=) holds 90 % of its blocks: the free view shows the nearest of them and says
//      how far it is complete, the sensor's render, through a window, is the same as before;
//      finally a map fused at the ground-truth poses,
//      opened with its occupancy grid (`serve --occupancy`), the streamed frames compared with
//      it at their ground truth, and the last render's unknown marks (asked of the bridge)
//      those `simulate --occupancy` writes at that pose;
//   8. plane segmentation (seed 003): the plane view, the world model of planes and its scene
//      .glb, its textured planes in the free view; then a fresh page segmenting the fused map
//      at each tracked pose (?planes_model=1), whose planes must be the frame's own.
// Prints one line per check and a closing "e2e: N passed, M failed"; exits non-zero on failure.
//
// usage: node tests/browser/e2e.mjs [--webfusion target/release/webfusion] [--dist dist]
//          [--sample data/sample/fr1_rpy.wfr] [--out out/e2e] [--map sparse|dense] [--volume 128]
//          [--voxel-mm 40]
// The main page fuses into --map (default sparse: the voxel-block map, the app's default); the
// second page fuses into the dense box, so both kinds run in the browser.
import { spawnSync } from 'node:child_process';
import { readdirSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { decodePng, evaluateWithin, launchChromium, options, parseTum, startBridge, waitFor, within } from './lib.mjs';

const { webfusion, dist, sample, out, map, volume, voxelMm } = options({ out: 'out/e2e', map: 'sparse', volume: 128, 'voxel-mm': 40 });
// Browser vs native positions, no alignment. The same WGSL runs on two adapters (SwiftShader,
// lavapipe) whose f32 arithmetic differs in the last bits; where a level's convergence test
// lands on different sides of its threshold the two runs take a different number of
// iterations and part ways by a few millimetres for the rest of the run (seen: fr1/rpy frame
// 53, 6.6 mm, then decaying). RMSE 5 mm and max 10 mm allow that, and no real divergence
// (centimetres).
const TOLERANCE_RMSE_M = 0.005;
const TOLERANCE_MAX_M = 0.010;
const FRAME_TIMEOUT_MS = 120_000;
// The whole run's limit (it takes 4-6 minutes here): whatever hangs, the run ends with a named
// failure instead of running into CI's own limit.
const RUN_TIMEOUT_MS = 30 * 60_000;
let stage = 'starting';
const watchdog = setTimeout(() => {
  console.log(`FAIL e2e run: still running after ${RUN_TIMEOUT_MS / 60_000} minutes, at: ${stage}`);
  console.log('e2e: gave up');
  if (bridge) bridge.child.kill('SIGKILL');
  process.exit(1);
}, RUN_TIMEOUT_MS);

/** A fresh page of `bridge` that opens the bridge's map (`serve --map`): the page, its page
 * errors, and its status once the map is open (or the page has said why not). */
async function openBridgeMap(browser, bridge, query = '') {
  const page = await browser.newPage({ viewport: { width: 1400, height: 1000 } });
  const errors = [];
  page.on('pageerror', (e) => errors.push(String(e)));
  await page.goto(`http://${bridge.addr}/${query}`);
  await waitFor(page, 'the link', (s) => s.link === 'connected', 60_000);
  await page.click('#map-from-bridge');
  const opened = await waitFor(page, 'the opened map', (s) => s.sensor?.map || s.message, 120_000);
  return { page, errors, opened };
}

const results = [];
function check(name, ok, detail) {
  results.push({ name, ok });
  console.log(`${ok ? 'PASS' : 'FAIL'} ${name}: ${detail}`);
}

let bridge = null;
let browser = null;
try {
  // 1. The native reference on the same frames and settings.
  const native = join(out, 'native');
  const t0 = Date.now();
  const run = spawnSync(webfusion, ['reconstruct', sample, '--out', native, '--map-kind', map, '--volume', String(volume), '--voxel-size', String(voxelMm / 1000), '--centred', '--no-mesh', '--save-map', join(out, 'native', 'map.wfm')], { encoding: 'utf8' });
  if (run.status !== 0) throw new Error(`webfusion reconstruct failed: ${run.stderr}`);
  const nativeTrajectory = parseTum(readFileSync(join(native, 'trajectory.txt'), 'utf8'));
  console.log(`native reference (${map} map): ${nativeTrajectory.length} frames in ${((Date.now() - t0) / 1000).toFixed(1)} s`);

  // 2. The bridge and the page.
  stage = 'the first page';
  bridge = await startBridge(webfusion, sample, dist, '127.0.0.1:0');
  const port = bridge.addr.split(':')[1];
  browser = await launchChromium();
  const page = await browser.newPage({ viewport: { width: 1400, height: 1000 } });
  const consoleErrors = [];
  // Chromium logs each refused reconnect attempt itself; those are expected while the bridge is down.
  page.on('console', (m) => { if (m.type() === 'error' && !m.text().includes('WebSocket connection to')) consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => consoleErrors.push(String(e)));
  const url = `http://${bridge.addr}/?map=${map}&volume=${volume}&voxel_mm=${voxelMm}&centred=1&autoplay=1`;
  const tOpen = Date.now();
  await page.goto(url);
  const first = await waitFor(page, 'the first frame', (s) => s.frames_done >= 1, FRAME_TIMEOUT_MS);
  console.log(`page: ${first.adapter}; first frame after ${((Date.now() - tOpen) / 1000).toFixed(1)} s (from connect: ${first.time_to_first_frame_ms?.toFixed(0)} ms; pipelines compiled by then: ${JSON.stringify(first.first_frame_kernels)}; milestones ${JSON.stringify(first.startup_ms)})`);
  const total = first.frames_total;

  // 3. Kill the bridge midway; start it again on the same port.
  stage = 'the reconnect';
  const midway = Math.floor(total / 3);
  await waitFor(page, `frame ${midway}`, (s) => s.frames_done >= midway, FRAME_TIMEOUT_MS * midway);
  bridge.child.kill('SIGKILL');
  const dropped = await waitFor(page, 'the page to notice the dropped bridge', (s) => s.link !== 'connected', 30_000);
  await new Promise((r) => setTimeout(r, 1500));
  bridge = await startBridge(webfusion, sample, dist, `127.0.0.1:${port}`);
  const resumed = await waitFor(page, 'the page to reconnect', (s) => s.reconnects >= 1 && s.link === 'connected' && s.frames_done > dropped.frames_done, 60_000);
  check('reconnect', true, `bridge killed at frame ${dropped.frames_done}; the page reconnected by itself (${resumed.reconnects} reconnect(s)) and fused frame ${resumed.frames_done}`);

  // 4. All frames, then compare with the native trajectory.
  stage = 'every frame';
  const tRun = Date.now();
  const done = await waitFor(page, 'every frame', (s) => s.frames_done >= total && s.state === 'ended', FRAME_TIMEOUT_MS * total);
  console.log(`browser: ${done.frames_done} frames, ${done.fps.toFixed(2)} fps over the last frames; stages (median ms) ${JSON.stringify(done.stages_ms)}; lost ${done.lost_frames}; ATE vs ground truth ${done.ate_rmse_m === null ? 'n/a' : (done.ate_rmse_m * 100).toFixed(2) + ' cm'}; ${((Date.now() - tRun) / 1000).toFixed(0)} s after the reconnect`);
  stage = 'comparing trajectories';
  const browserTum = await evaluateWithin(page, () => window.webfusion.trajectory_tum(), 'the trajectory');
  writeFileSync(join(out, 'browser_trajectory.txt'), browserTum);
  const browserTrajectory = parseTum(browserTum);
  const byTime = new Map(nativeTrajectory.map((p) => [p.t.toFixed(6), p.p]));
  let sumSq = 0, max = 0, pairs = 0;
  for (const { t, p } of browserTrajectory) {
    const q = byTime.get(t.toFixed(6));
    if (!q) continue;
    const d = Math.hypot(p[0] - q[0], p[1] - q[1], p[2] - q[2]);
    sumSq += d * d; max = Math.max(max, d); pairs++;
  }
  const rmse = Math.sqrt(sumSq / Math.max(pairs, 1));
  check('trajectory matches native', pairs === nativeTrajectory.length && browserTrajectory.length === nativeTrajectory.length && rmse < TOLERANCE_RMSE_M && max < TOLERANCE_MAX_M,
    `${pairs} of ${nativeTrajectory.length} poses paired; browser vs native RMSE ${(rmse * 1000).toFixed(3)} mm, max ${(max * 1000).toFixed(3)} mm (limits ${TOLERANCE_RMSE_M * 1000} and ${TOLERANCE_MAX_M * 1000} mm, no alignment)`);

  const v = done.volume;
  check('the map reports its use', v.kind === map && (map !== 'sparse' || (v.blocks_used > 100 && v.blocks_used <= v.pool_blocks && !v.full)),
    `${v.kind} map: ${v.blocks_used} of ${v.pool_blocks} blocks used, full ${v.full}, ${(v.memory_bytes / 1048576).toFixed(0)} MiB`);

  // 5. The free 3D view shows the model.
  stage = 'the screenshot and the exports';
  const shot = await page.locator('#view-free').screenshot({ path: join(out, 'free_view.png') });
  const png = decodePng(shot);
  let lit = 0;
  const greys = new Set();
  for (let i = 0; i < png.width * png.height; i++) {
    const [r, g, b] = [png.pixels[i * png.channels], png.pixels[i * png.channels + 1], png.pixels[i * png.channels + 2]];
    if (r + g + b > 60) lit++;
    greys.add(r >> 3);
  }
  const fraction = lit / (png.width * png.height);
  check('screenshot shows the model', fraction > 0.15 && greys.size > 8, `${(fraction * 100).toFixed(1)} % of ${png.width}x${png.height} pixels lit, ${greys.size} distinct shades (saved ${join(out, 'free_view.png')})`);
  // 6. The exports arrive as downloads: a binary PLY with a real mesh, and the trajectory.
  const [plyDownload] = await Promise.all([page.waitForEvent('download', { timeout: 300_000 }), page.click('#export-ply')]);
  const plyPath = join(out, 'browser_mesh.ply');
  await plyDownload.saveAs(plyPath);
  const ply = readFileSync(plyPath);
  const header = ply.subarray(0, 1024).toString('latin1');
  const vertices = Number(header.match(/element vertex (\d+)/)?.[1] ?? 0);
  const faces = Number(header.match(/element face (\d+)/)?.[1] ?? 0);
  const headerEnd = header.indexOf('end_header\n') + 'end_header\n'.length;
  const plyBytes = headerEnd + vertices * (6 * 4 + 3) + faces * (1 + 3 * 4);
  const [tumDownload] = await Promise.all([page.waitForEvent('download', { timeout: 60_000 }), page.click('#export-trajectory')]);
  const tumText = readFileSync(await tumDownload.path(), 'utf8');
  check('exports', header.startsWith('ply\nformat binary_little_endian') && vertices > 1000 && faces > 1000 && ply.length === plyBytes && tumText === browserTum,
    `mesh.ply ${vertices} vertices, ${faces} triangles, ${ply.length} bytes (expected ${plyBytes}); trajectory.txt ${tumText === browserTum ? 'equals' : 'DIFFERS from'} the hook's`);
  const final = await evaluateWithin(page, () => window.webfusion.status, 'the final status');
  check('no page errors', consoleErrors.length === 0 && final.message === '', consoleErrors.length ? consoleErrors.join(' | ') : `status message "${final.message}"`);
  console.log(`host per frame: ${JSON.stringify(final.host_per_frame)}; GPU timestamps: ${final.gpu_timestamps}; time to first frame ${final.time_to_first_frame_ms?.toFixed(0)} ms`);
  check('one submission and one late readback per frame', final.host_per_frame.submits === 1 && final.host_per_frame.readbacks === 1 && final.host_per_frame.host_waits <= 1,
    `the last frame's pipeline: ${JSON.stringify(final.host_per_frame)}`);

  // 6b. Feature odometry (on by default): its view shows the last pair with RANSAC's inliers,
  // and its step button walks through the stages (past the last it fetches the next frame).
  stage = 'the odometry view';
  const fv = final.features;
  const odoShot = decodePng(await page.locator('#view-odometry').screenshot({ path: join(out, 'odometry_view.png') }));
  let odoLit = 0;
  for (let i = 0; i < odoShot.width * odoShot.height; i++) {
    if (odoShot.pixels[i * odoShot.channels] + odoShot.pixels[i * odoShot.channels + 1] + odoShot.pixels[i * odoShot.channels + 2] > 60) odoLit++;
  }
  check('feature odometry view', fv && fv.pair && fv.pair.inliers >= 20 && fv.pair.matches >= fv.pair.inliers && fv.pair.stage === 'estimation' && fv.guesses >= total - 2 && odoLit / (odoShot.width * odoShot.height) > 0.3,
    `features ${JSON.stringify(fv)}; view ${(100 * odoLit / (odoShot.width * odoShot.height)).toFixed(0)} % lit (saved ${join(out, 'odometry_view.png')})`);
  // The page handles each click in its event loop: wait for each step to show.
  await page.click('#odometry-step');
  await waitFor(page, 'the first stage step', (s) => s.features?.pair?.stage === 'update', 30_000);
  await page.click('#odometry-step');
  const stepped = await waitFor(page, 'the second stage step', (s) => s.features?.pair?.stage === 'detection', 30_000);
  check('odometry stage steps', stepped.features.pair.stage === 'detection' && stepped.frames_done === final.frames_done, `estimation -> update (at the end of the log no frame is requested) -> detection: "${await page.locator('#odometry-stage').textContent()}"`);

  // 6c. Plane segmentation (on by default): the plane view colours the last frame's planes,
  // and the status lists them (the sample's desk and partition face the camera).
  stage = 'the plane view';
  const pv = final.planes;
  const planeShot = decodePng(await page.locator('#view-planes').screenshot({ path: join(out, 'planes_view.png') }));
  let saturated = 0;
  for (let i = 0; i < planeShot.width * planeShot.height; i++) {
    const [r, g, b] = [planeShot.pixels[i * planeShot.channels], planeShot.pixels[i * planeShot.channels + 1], planeShot.pixels[i * planeShot.channels + 2]];
    if (Math.max(r, g, b) - Math.min(r, g, b) > 60) saturated++;
  }
  const planeFraction = saturated / (planeShot.width * planeShot.height);
  check('plane view', pv && pv.count >= 2 && pv.frame === final.last_index && pv.planes.every((p) => Math.abs(Math.hypot(...p.normal) - 1) < 1e-3 && p.offset_m > 0 && p.pixels > 0) && planeFraction > 0.1,
    `planes ${JSON.stringify(pv && { frame: pv.frame, count: pv.count, pixels: pv.planes.map((p) => p.pixels), median_ms: pv.median_ms })}; view ${(100 * planeFraction).toFixed(0)} % plane-coloured (saved ${join(out, 'planes_view.png')})`);

  // 6c'. The world model of planes (a frame about once a second joins it, at its tracked pose)
  // and its scene: one textured mesh per world plane plus the fused mesh less what they cover.
  stage = 'the scene export';
  const world = final.world;
  const [sceneDownload] = await Promise.all([page.waitForEvent('download', { timeout: 300_000 }), page.click('#export-scene')]);
  const glb = readFileSync(await sceneDownload.path());
  const jsonLength = glb.readUInt32LE(12);
  const gltf = JSON.parse(glb.subarray(20, 20 + jsonLength).toString('utf8'));
  const textured = gltf.meshes.length - 1;
  const rest = gltf.meshes[gltf.meshes.length - 1].primitives[0];
  const restTriangles = gltf.accessors[rest.indices].count / 3;
  check('world planes and the scene .glb', world && world.frames >= 2 && world.planes >= 2 && glb.subarray(0, 4).toString('latin1') === 'glTF' && glb.readUInt32LE(8) === glb.length
    && textured === world.planes && gltf.images.length === world.planes && rest.attributes.COLOR_0 !== undefined && restTriangles > 0 && restTriangles < faces,
    `world ${JSON.stringify(world)}; scene.glb ${glb.length} bytes: ${textured} textured plane meshes, ${gltf.images.length} textures, remainder ${restTriangles} of the mesh's ${faces} triangles`);

  // 6c''. The world's textured planes in the free view (the plane_overlay kernel over the
  // raycast): with them off the view is the model's grey shading; on, every world plane is
  // drawn and the pixels on the desk and the partition take their texture's colours.
  stage = 'the textured planes in the free view';
  const freeShot = async (name) => decodePng(await page.locator('#view-free').screenshot({ path: join(out, name) }));
  await page.uncheck('#free-planes');
  await waitFor(page, 'the free view without planes', (s) => s.world?.drawn?.planes === 0, 30_000);
  const bare = await freeShot('free_view_no_planes.png');
  await page.check('#free-planes');
  const drawnState = await waitFor(page, 'the free view with planes', (s) => s.world?.drawn?.planes > 0 && s.world.drawn.planes === s.world.planes, 30_000);
  const withPlanes = await freeShot('free_view_planes.png');
  let changed = 0;
  let coloured = 0;
  for (let i = 0; i < bare.width * bare.height; i++) {
    const o = i * bare.channels;
    const [r, g, b] = [withPlanes.pixels[o], withPlanes.pixels[o + 1], withPlanes.pixels[o + 2]];
    if (Math.abs(r - bare.pixels[o]) + Math.abs(g - bare.pixels[o + 1]) + Math.abs(b - bare.pixels[o + 2]) > 24) changed++;
    if (Math.max(r, g, b) - Math.min(r, g, b) > 12) coloured++;
  }
  const n = bare.width * bare.height;
  check('textured planes in the free view', drawnState.world.drawn.left_out === 0 && drawnState.world.drawn.texels > 0 && changed / n > 0.03 && coloured / n > 0.03,
    `drawn ${JSON.stringify(drawnState.world.drawn)} of ${drawnState.world.planes} world planes; ${(100 * changed / n).toFixed(1)} % of the pixels changed, ${(100 * coloured / n).toFixed(1)} % coloured (saved free_view_no_planes.png, free_view_planes.png)`);

  // 6d. The virtual sensor in the fused map at the last frame's tracked pose, beside that
  // frame's real depth: the model explains the frame it was fused from (bounds from the
  // voxel size: 4 cm voxels blur depth edges; measured coverage 90.2 %, 1.8 % of pixels over
  // 10 %, median 5.8 mm), then with the Kinect noise model, whose
  // dropouts leave fewer valid pixels; the last render downloads as 16-bit PNG.
  stage = 'the virtual sensor';
  await page.click('#sim-at-frame');
  const exact = (await waitFor(page, 'the virtual sensor at the last frame', (s) => s.sensor?.last?.compare && s.sensor.last.frame === final.last_index, 120_000)).sensor.last;
  const ec = exact.compare;
  const simShot = decodePng(await page.locator('#view-sim').screenshot({ path: join(out, 'sim_view.png') }));
  let simLit = 0;
  for (let i = 0; i < simShot.width * simShot.height; i++) {
    if (simShot.pixels[i * simShot.channels] + simShot.pixels[i * simShot.channels + 1] + simShot.pixels[i * simShot.channels + 2] > 60) simLit++;
  }
  check('virtual sensor at the last frame', ec.coverage_percent > 85 && ec.pixels_rel_error_over_10pct_percent < 5 && ec.median_abs_error_mm < 15 && exact.noise_seed === null && simLit / (simShot.width * simShot.height) > 0.3,
    `frame ${exact.frame}: ${JSON.stringify(ec)}; ${exact.valid_pixels} valid pixels; view ${(100 * simLit / (simShot.width * simShot.height)).toFixed(0)} % lit (saved ${join(out, 'sim_view.png')})`);
  await page.check('#sim-noise');
  const noisy = (await waitFor(page, 'the noisy render', (s) => s.sensor?.last?.noise_seed === 1 && s.sensor.last.compare, 120_000)).sensor.last;
  const [simDownload] = await Promise.all([page.waitForEvent('download', { timeout: 60_000 }), page.click('#sim-download')]);
  const simPng = decodePng(readFileSync(await simDownload.path()));
  const simValid = simPng.depth16.reduce((n, u) => n + (u > 0 ? 1 : 0), 0);
  check('virtual sensor with Kinect noise, downloaded', noisy.frame === exact.frame && noisy.valid_pixels < exact.valid_pixels && noisy.compare.coverage_percent > 75 && simPng.width === noisy.width_px && simPng.height === noisy.height_px && simValid === noisy.valid_pixels && simDownload.suggestedFilename() === `sim_depth_frame${noisy.frame}_noise1.png`,
    `${noisy.valid_pixels} valid pixels with noise vs ${exact.valid_pixels} exact; ${JSON.stringify(noisy.compare)}; ${simDownload.suggestedFilename()} ${simPng.width}x${simPng.height}, ${simValid} non-zero`);

  // A pose picked from the trajectory: the first fused frame's (no real depth is kept for it).
  const before = (await evaluateWithin(page, () => window.webfusion.status, 'the status')).sensor.rendered;
  await page.fill('#sim-trajectory', '0');
  await page.click('#sim-at-trajectory');
  const picked = (await waitFor(page, 'the render at trajectory pose 0', (s) => s.sensor?.rendered > before && s.sensor.in_flight === 0, 120_000)).sensor.last;
  const p0 = browserTrajectory[0].p;
  await page.fill('#sim-trajectory', '100000');
  await page.click('#sim-at-trajectory');
  const noPose = await waitFor(page, 'the refused trajectory pose', (s) => /no pose 100000/.test(s.message), 30_000);
  check('virtual sensor at a trajectory pose', Math.hypot(picked.pose[0] - p0[0], picked.pose[1] - p0[1], picked.pose[2] - p0[2]) < 1e-4 && picked.compare === null && picked.valid_pixels > 0.3 * picked.width_px * picked.height_px && noPose.sensor.rendered === before + 1,
    `pose ${JSON.stringify(picked.pose.map((v) => +v.toFixed(4)))} (trajectory pose 0 at ${JSON.stringify(p0.map((v) => +v.toFixed(4)))}); ${picked.valid_pixels} valid pixels; index 100000: "${noPose.message}"`);

  // 6e. Planes of the fused map (`?planes_model=1`): a fresh page replays the log segmenting
  // the map's depth at each tracked pose instead of the frame's (a virtual sensor rendering
  // straight into a preprocessor of its own). At the last frame the map's planes are the
  // frame's planes: each large one (a tenth of the image or more) lies within 5° and 5 cm
  // of a plane the first page found in the same frame's own depth.
  stage = 'the planes of the fused map';
  const modelPage = await browser.newPage({ viewport: { width: 1400, height: 1000 } });
  const modelErrors = [];
  modelPage.on('pageerror', (e) => modelErrors.push(String(e)));
  await modelPage.goto(`http://${bridge.addr}/?map=${map}&volume=${volume}&voxel_mm=${voxelMm}&centred=1&features=0&planes_model=1&autoplay=1`);
  const modelDone = await waitFor(modelPage, 'every frame, planes of the fused map', (s) => s.frames_done >= total && s.state === 'ended' && s.planes?.frame === s.last_index, FRAME_TIMEOUT_MS * total);
  const mp = modelDone.planes;
  const pixels = 640 * 480;
  const matched = (p) => pv.planes.some((q) => Math.acos(Math.min(1, p.normal[0] * q.normal[0] + p.normal[1] * q.normal[1] + p.normal[2] * q.normal[2])) < 5 * Math.PI / 180 && Math.abs(p.offset_m - q.offset_m) < 0.05);
  const large = mp ? mp.planes.filter((p) => p.pixels >= pixels / 10) : [];
  check('planes of the fused map', mp && mp.source === 'fused_map' && pv.source === 'frames' && mp.frame === pv.frame && mp.count >= 2 && large.length >= 1 && large.every(matched)
    && modelDone.world.frames >= 2 && modelDone.world.planes >= 2 && modelErrors.length === 0 && modelDone.message === '',
    `frame ${mp?.frame}: ${JSON.stringify(mp && mp.planes.map((p) => ({ n: p.normal.map((v) => +v.toFixed(3)), d: +p.offset_m.toFixed(3), px: p.pixels })))} against the frame's ${JSON.stringify(pv.planes.map((p) => ({ n: p.normal.map((v) => +v.toFixed(3)), d: +p.offset_m.toFixed(3), px: p.pixels })))}; world ${JSON.stringify(modelDone.world)}; ${mp?.median_ms.toFixed(0)} ms/frame${modelErrors.length ? '; page errors: ' + modelErrors.join(' | ') : ''}`);
  await within(modelPage.close(), 30_000);

  // 7. Bad settings in the URL, then a lost device, in a browser of their own (a fresh GPU
  // process, as a new visitor would have).
  stage = 'the second browser';
  await within(browser.close(), 30_000);
  browser = await launchChromium();
  const second = await browser.newPage({ viewport: { width: 1400, height: 1000 } });
  const secondErrors = [];
  second.on('pageerror', (e) => secondErrors.push(String(e)));
  await second.goto(`http://${bridge.addr}/?map=dense&volume=${volume}&voxel_mm=abc&map_mib=0&rate=NaN&centred=1&autoplay=1`);
  const fallback = await waitFor(second, 'frames with fallback settings', (s) => s.frames_done >= 3, FRAME_TIMEOUT_MS * 3);
  check('bad URL settings fall back with a message', /voxel_mm=abc ignored/.test(fallback.message) && /map_mib=0 ignored \(invalid configuration: map memory 0 MiB/.test(fallback.message) && /rate ignored/.test(fallback.message) && fallback.reconnects === 0 && fallback.volume.voxel_size_m > 0,
    `message "${fallback.message}"; voxel ${(fallback.volume.voxel_size_m * 1000).toFixed(1)} mm; reconnects ${fallback.reconnects}`);
  stage = 'the lost device';
  await evaluateWithin(second, () => window.webfusion.lose_device(), 'losing the device');
  // The loss may show as an error for a moment before the rebuild: poll without failing on it.
  let rebuilt = null;
  for (const deadline = Date.now() + FRAME_TIMEOUT_MS * 4; Date.now() < deadline; await new Promise((r) => setTimeout(r, 250))) {
    const s = await evaluateWithin(second, () => window.webfusion.status, 'waiting for the rebuild');
    if (s.device_rebuilds >= 1 && s.frames_done >= fallback.frames_done + 3) { rebuilt = s; break; }
  }
  if (!rebuilt) throw new Error(`no rebuild after the lost device: ${JSON.stringify(await evaluateWithin(second, () => window.webfusion.status, 'the status after no rebuild'))}`);
  check('a lost device is rebuilt and fusing resumes', rebuilt.state !== 'error' && secondErrors.length === 0 && rebuilt.last_index > fallback.last_index,
    `${rebuilt.device_rebuilds} rebuild(s); frames ${fallback.frames_done} -> ${rebuilt.frames_done}, last index ${fallback.last_index} -> ${rebuilt.last_index}; state ${rebuilt.state}${secondErrors.length ? '; page errors: ' + secondErrors.join(' | ') : ''}`);
  await within(second.close(), 30_000);

  // 8. The native run's saved map, offered by `serve --map`, opened in a fresh page: explored
  // without fusing, and the virtual sensor placed at a pose of the native trajectory renders
  // what `webfusion simulate` renders there (the same kernels on SwiftShader and lavapipe:
  // rays that graze an edge may hit on one and miss on the other, nothing more).
  stage = 'the saved map';
  const mapPath = join(out, 'native', 'map.wfm');
  const mapBytes = readFileSync(mapPath);
  const mapBlocks = Number(mapBytes.readBigUInt64LE(mapBytes.length - 16));
  bridge.child.kill('SIGKILL');
  bridge = await startBridge(webfusion, sample, dist, '127.0.0.1:0', ['--map', mapPath]);
  const { page: third, errors: thirdErrors, opened } = await openBridgeMap(browser, bridge);
  const om = opened.sensor.map;
  await new Promise((r) => setTimeout(r, 2000));
  const mapShot = decodePng(await third.locator('#view-free').screenshot({ path: join(out, 'opened_map_view.png') }));
  let mapLit = 0;
  for (let i = 0; i < mapShot.width * mapShot.height; i++) {
    if (mapShot.pixels[i * mapShot.channels] + mapShot.pixels[i * mapShot.channels + 1] + mapShot.pixels[i * mapShot.channels + 2] > 60) mapLit++;
  }
  // The virtual Kinect placed at the free view's camera sees the map too.
  await third.click('#sim-from-view');
  const fromView = (await waitFor(third, 'the render at the free view', (s) => s.sensor?.rendered >= 1 && s.sensor.in_flight === 0, 120_000)).sensor.last;
  check('a saved map opens from the bridge', om && om.blocks === mapBlocks && om.kind === map && om.frame === 'first camera' && !om.damage && opened.frames_done === 0 && mapLit / (mapShot.width * mapShot.height) > 0.1 && fromView.valid_pixels > 0.1 * fromView.width_px * fromView.height_px && fromView.compare === null,
    `${JSON.stringify(om ?? opened.message)} (the file has ${mapBlocks} blocks); free view ${(100 * mapLit / (mapShot.width * mapShot.height)).toFixed(0)} % lit (saved ${join(out, 'opened_map_view.png')}); the sensor at the free view: ${fromView.valid_pixels} valid pixels, no real frame`);
  const poseLine = readFileSync(join(native, 'trajectory.txt'), 'utf8').split('\n').filter((l) => l && !l.startsWith('#'))[Math.floor(nativeTrajectory.length / 2)];
  writeFileSync(join(out, 'sim_pose.txt'), poseLine + '\n');
  const simDir = join(out, 'native_sim');
  // simulate never writes over a simulation: a directory left by an earlier run goes first.
  rmSync(simDir, { recursive: true, force: true });
  const simRun = spawnSync(webfusion, ['simulate', '--map', mapPath, '--poses', join(out, 'sim_pose.txt'), '--out', simDir], { encoding: 'utf8' });
  if (simRun.status !== 0) throw new Error(`webfusion simulate failed: ${simRun.stderr}`);
  const nativeSim = decodePng(readFileSync(join(simDir, 'depth', readdirSync(join(simDir, 'depth'))[0]))).depth16;
  await third.fill('#sim-pose', poseLine.split(/\s+/).slice(1, 8).join(' '));
  await third.click('#sim-render');
  await waitFor(third, 'the render at the native pose', (s) => s.sensor?.rendered >= 2 && s.sensor.in_flight === 0, 120_000);
  const [placedDownload] = await Promise.all([third.waitForEvent('download', { timeout: 60_000 }), third.click('#sim-download')]);
  const placed = decodePng(readFileSync(await placedDownload.path())).depth16;
  /** Pixels valid in both depth images, within 2 units of each other, and valid in only one. */
  function agreement(placed) {
    let onlyOne = 0, both = 0, close = 0, valid = 0;
    for (let i = 0; i < placed.length; i++) {
      const [a, b] = [placed[i], nativeSim[i]];
      if (a > 0 || b > 0) valid++;
      if ((a > 0) !== (b > 0)) onlyOne++;
      else if (a > 0) { both++; if (Math.abs(a - b) <= 2) close++; }
    }
    const ok = placed.length === nativeSim.length && both > 0.3 * placed.length && onlyOne <= 0.02 * valid && close >= 0.99 * both;
    return { ok, text: `${both} pixels valid in both, ${(100 * close / Math.max(both, 1)).toFixed(2)} % within 2 units (0.4 mm); ${onlyOne} valid in only one (${(100 * onlyOne / Math.max(valid, 1)).toFixed(2)} %)` };
  }
  const placedAgreement = agreement(placed);
  check('the placed virtual sensor renders what simulate does', placedAgreement.ok, placedAgreement.text);
  await third.fill('#sim-pose', '1 2');
  await third.click('#sim-render');
  const refused = await waitFor(third, 'the refused pose', (s) => /7 numbers/.test(s.message), 30_000);
  check('a malformed sensor pose is named, not rendered', refused.sensor.rendered === 2 && thirdErrors.length === 0, `message "${refused.message}"${thirdErrors.length ? '; page errors: ' + thirdErrors.join(' | ') : ''}`);
  await within(third.close(), 30_000);

  // The same map in a page whose map memory holds 90 % of its blocks (the sensor's view at the
  // native pose reaches about 80 %; the free view's first look, all of them): the map is
  // windowed, the free view shows its nearest blocks and says how far it is complete, and the
  // sensor's render at the native pose, through a window that holds all of its view, is what
  // simulate renders there.
  const windowedMib = (0.9 * om.memory_bytes / 1048576).toFixed(4);
  const { page: small, errors: smallErrors, opened: smallOpened } = await openBridgeMap(browser, bridge, `?map_mib=${windowedMib}`);
  const freeNearest = await waitFor(small, 'the free view through a window', (s) => s.sensor?.map?.free_view_complete_within_m != null || s.message, 120_000);
  await small.fill('#sim-pose', poseLine.split(/\s+/).slice(1, 8).join(' '));
  await small.click('#sim-render');
  const smallRendered = await waitFor(small, 'the windowed render at the native pose', (s) => (s.sensor?.rendered >= 1 && s.sensor.in_flight === 0) || /sensor/.test(s.message ?? ''), 120_000);
  const [smallDownload] = await Promise.all([small.waitForEvent('download', { timeout: 60_000 }), small.click('#sim-download')]);
  const windowedAgreement = agreement(decodePng(readFileSync(await smallDownload.path())).depth16);
  const sm = smallRendered.sensor.map;
  const fm = freeNearest.sensor?.map;
  check('a map larger than the page\'s map memory is shown and rendered through a window', smallOpened.sensor?.map?.blocks === mapBlocks && sm.pool_blocks < mapBlocks && sm.windows >= 1 && fm?.free_view_left_out > 0 && fm.free_view_complete_within_m > 0 && windowedAgreement.ok && smallErrors.length === 0,
    `map memory ${windowedMib} MiB: pool ${sm.pool_blocks} of ${mapBlocks} blocks, ${sm.windows} windows; the free view left ${fm?.free_view_left_out} blocks out, complete within ${fm?.free_view_complete_within_m?.toFixed(2)} m${freeNearest.message ? ' (message: ' + freeNearest.message + ')' : ''}; the sensor through the window: ${windowedAgreement.text}${smallErrors.length ? '; page errors: ' + smallErrors.join(' | ') : ''}`);
  await within(small.close(), 30_000);

  // 9. Seed 000's experiment, live: a map fused natively at the sample's ground-truth poses,
  // opened from the bridge; the frames then streamed are not fused but compared, each at its
  // ground-truth pose, with the virtual sensor's view of the map ("follow frames").
  stage = 'sim vs real at ground truth';
  const gtMapPath = join(out, 'gt_map.wfm');
  const gtRun = spawnSync(webfusion, ['reconstruct', sample, '--out', join(out, 'native_gt'), '--poses', join(native, 'groundtruth.txt'), '--map-kind', map, '--voxel-size', String(voxelMm / 1000), '--no-mesh', '--save-map', gtMapPath], { encoding: 'utf8' });
  if (gtRun.status !== 0) throw new Error(`webfusion reconstruct --poses failed: ${gtRun.stderr}`);
  // Its occupancy grid (5 cm cells, 8 m about the cameras' mean), carved from those poses, lets
  // the bridge mark the pixels whose ray crossed never-observed space.
  const gtPoses = parseTum(readFileSync(join(out, 'native_gt', 'trajectory.txt'), 'utf8'));
  const mean = [0, 1, 2].map((a) => gtPoses.reduce((sum, p) => sum + p.p[a], 0) / gtPoses.length);
  const gridPath = join(out, 'gt_grid.bin');
  const gridJson = join(out, 'gt_grid.json');
  const gridRun = spawnSync(webfusion, ['export-occupancy', '--map', gtMapPath, '--out', gridPath, '--voxel-size', '0.05', '--dims', '160,160,160', '--center', mean.map((v) => v.toFixed(3)).join(','), '--poses', join(out, 'native_gt', 'trajectory.txt')], { encoding: 'utf8' });
  if (gridRun.status !== 0) throw new Error(`webfusion export-occupancy failed: ${gridRun.stderr}`);
  bridge.child.kill('SIGKILL');
  bridge = await startBridge(webfusion, sample, dist, '127.0.0.1:0', ['--map', gtMapPath, '--occupancy', gridJson]);
  const { page: fourth, errors: fourthErrors } = await openBridgeMap(browser, bridge);
  await fourth.check('#sim-follow');
  await fourth.click('#play');
  const live = await waitFor(fourth, 'three compared frames', (s) => s.sensor?.rendered >= 3 && s.sensor.last?.compare && s.sensor.last.frame > 0, FRAME_TIMEOUT_MS * 3);
  await fourth.click('#pause');
  const lc = live.sensor.last.compare;
  // The map names the world's up (the mean of its cameras' up axes), which the free view orbits about.
  const up = live.sensor.map.up_in_map;
  const upUnit = Array.isArray(up) && Math.abs(Math.hypot(...up) - 1) < 1e-3;
  check('frames compared at their ground truth, not fused', live.sensor.map.frame === 'given poses' && upUnit && live.frames_done === 0 && lc.coverage_percent > 70 && lc.pixels_rel_error_over_10pct_percent < 25 && fourthErrors.length === 0,
    `frame ${live.sensor.last.frame}: ${JSON.stringify(lc)}; up ${JSON.stringify(up)}; ${live.sensor.rendered} renders, ${live.sensor.skipped} frames skipped while the sensor was busy; fused ${live.frames_done}${fourthErrors.length ? '; page errors: ' + fourthErrors.join(' | ') : ''}`);
  // The unknown marks over the last render: the bridge's mask at its pose, which is what
  // `simulate --occupancy` marks there natively.
  const marked = await waitFor(fourth, 'the last render\'s unknown mask', (s) => s.sensor.in_flight === 0 && !s.sensor.unknown.asked && s.sensor.unknown.marked_render === s.sensor.rendered - 1, 120_000);
  const mu = marked.sensor.unknown;
  const markPose = marked.sensor.last.pose;
  writeFileSync(join(out, 'unknown_pose.txt'), `0 ${markPose.join(' ')}\n`);
  const unknownDir = join(out, 'native_unknown');
  rmSync(unknownDir, { recursive: true, force: true });
  const unknownRun = spawnSync(webfusion, ['simulate', '--map', gtMapPath, '--poses', join(out, 'unknown_pose.txt'), '--out', unknownDir, '--occupancy', gridJson], { encoding: 'utf8' });
  if (unknownRun.status !== 0) throw new Error(`webfusion simulate --occupancy failed: ${unknownRun.stderr}`);
  const nativeMask = decodePng(readFileSync(join(unknownDir, 'unknown', readdirSync(join(unknownDir, 'unknown'))[0]))).pixels;
  const nativePercent = 100 * nativeMask.reduce((n, v) => n + (v > 0 ? 1 : 0), 0) / nativeMask.length;
  const tint = decodePng(await fourth.locator('#view-sim-unknown').screenshot({ path: join(out, 'sim_unknown_view.png') }));
  let magenta = 0;
  for (let i = 0; i < tint.width * tint.height; i++) {
    const [r, g, b] = [tint.pixels[i * tint.channels], tint.pixels[i * tint.channels + 1], tint.pixels[i * tint.channels + 2]];
    if (r > 120 && b > 120 && g < 0.6 * Math.min(r, b)) magenta++;
  }
  check('unknown marks from the bridge', mu.unavailable === null && mu.marked_percent > 0.5 && mu.marked_percent < 99.5 && Math.abs(mu.marked_percent - nativePercent) < 0.5 && magenta > 0.002 * tint.width * tint.height && fourthErrors.length === 0,
    `${mu.marked_percent?.toFixed(2)} % of render ${mu.marked_render}'s pixels looked through never-observed space (simulate --occupancy at that pose: ${nativePercent.toFixed(2)} %); ${mu.stale} stale masks; ${(100 * magenta / (tint.width * tint.height)).toFixed(1)} % of the view tinted (saved sim_unknown_view.png)${fourthErrors.length ? '; page errors: ' + fourthErrors.join(' | ') : ''}`);
  await within(fourth.close(), 30_000);
} catch (error) {
  check('e2e run', false, `${error.stack ?? String(error)} (at: ${stage})`);
} finally {
  if (browser) await within(browser.close().catch(() => {}), 30_000);
  if (bridge) bridge.child.kill('SIGKILL');
  clearTimeout(watchdog);
}
const failed = results.filter((r) => !r.ok).length;
console.log(`e2e: ${results.length - failed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
