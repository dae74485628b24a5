// SPDX-License-Identifier: MIT
// Helpers shared by the end-to-end test and the browser benchmark: the bridge process,
// Chromium with WebGPU, the page's status hook, TUM trajectories and PNG pixels.
import { spawn } from 'node:child_process';
import { mkdirSync } from 'node:fs';
import { resolve } from 'node:path';
import { inflateSync } from 'node:zlib';
import { chromium } from 'playwright-core';

/**
 * The scripts' command line: `--webfusion`, `--dist`, `--sample`, `--out`, `--volume`,
 * `--voxel-mm` and any other `--name value` a script defaults, with the given defaults; paths
 * resolved, `out` created.
 */
export function options(defaults) {
  const given = Object.fromEntries(process.argv.slice(2).reduce((pairs, a, i, all) => (a.startsWith('--') ? [...pairs, [a.slice(2), all[i + 1]]] : pairs), []));
  const o = { webfusion: 'target/release/webfusion', dist: 'dist', sample: 'data/sample/fr1_rpy.wfr', ...defaults, ...given };
  const out = resolve(o.out);
  mkdirSync(out, { recursive: true });
  return { ...o, webfusion: resolve(o.webfusion), dist: resolve(o.dist), sample: resolve(o.sample), out, map: o.map, volume: Number(o.volume), voxelMm: Number(o['voxel-mm']) };
}

/** Chromium flags that give WebGPU (SwiftShader) and a visible canvas, headless (see ../shared/TOOLCHAIN.md). */
export const CHROMIUM_ARGS = ['--no-sandbox', '--enable-unsafe-webgpu', '--use-angle=swiftshader', '--use-webgpu-adapter=opengles', '--ignore-gpu-blocklist',
  '--disable-background-networking', '--disable-component-update', '--disable-sync', '--no-first-run', '--disable-quic'];

export function launchChromium() {
  return chromium.launch({ executablePath: process.env.CHROMIUM ?? '/usr/bin/chromium', headless: true, args: CHROMIUM_ARGS });
}

/** Starts `webfusion serve` on `bind` (with `extra` arguments) and resolves with its address once it prints its URL. */
export function startBridge(webfusion, sample, dist, bind, extra = []) {
  const child = spawn(webfusion, ['serve', '--source', sample, '--bind', bind, '--web-dir', dist, ...extra], { stdio: ['ignore', 'pipe', 'inherit'] });
  return new Promise((resolveAddr, reject) => {
    let text = '';
    child.stdout.on('data', (chunk) => {
      text += chunk;
      const m = text.match(/http:\/\/([^/\s]+)\//);
      if (m) resolveAddr({ child, addr: m[1] });
    });
    child.on('exit', (code) => reject(new Error(`webfusion serve exited (${code}) before printing its URL`)));
  });
}

/** TUM trajectory text -> [{t, p: [x, y, z]}]. */
export function parseTum(text) {
  return text.split('\n').filter((l) => l.trim() && !l.startsWith('#')).map((l) => {
    const v = l.trim().split(/\s+/).map(Number);
    return { t: v[0], p: [v[1], v[2], v[3]] };
  });
}

/**
 * Decodes a non-interlaced PNG, 8-bit RGB/RGBA (what Chromium writes), 8-bit grayscale (masks) or 16-bit grayscale
 * (depth, the TUM format) to {width, height, channels, pixels} (bytes), plus `depth16` (the
 * 16-bit values) for the latter.
 */
export function decodePng(buffer) {
  let offset = 8;
  let width = 0, height = 0, channels = 0, bitDepth = 8;
  const idat = [];
  while (offset < buffer.length) {
    const length = buffer.readUInt32BE(offset);
    const type = buffer.toString('ascii', offset + 4, offset + 8);
    const data = buffer.subarray(offset + 8, offset + 8 + length);
    if (type === 'IHDR') {
      width = data.readUInt32BE(0); height = data.readUInt32BE(4);
      const [depth, colour, , , interlace] = [data[8], data[9], data[10], data[11], data[12]];
      const rgb = depth === 8 && (colour === 2 || colour === 6);
      const grey16 = depth === 16 && colour === 0;
      const grey8 = depth === 8 && colour === 0;
      if (interlace !== 0 || !(rgb || grey16 || grey8)) throw new Error(`unsupported PNG (depth ${depth}, colour type ${colour}, interlace ${interlace})`);
      channels = colour === 6 ? 4 : colour === 2 ? 3 : 1;
      bitDepth = depth;
    } else if (type === 'IDAT') idat.push(data);
    offset += 12 + length;
  }
  const raw = inflateSync(Buffer.concat(idat));
  // Filters work on bytes, each against the byte one pixel (bpp bytes) to the left.
  const bpp = channels * (bitDepth / 8);
  const stride = width * bpp;
  const pixels = Buffer.alloc(stride * height);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    for (let x = 0; x < stride; x++) {
      const cur = raw[y * (stride + 1) + 1 + x];
      const a = x >= bpp ? pixels[y * stride + x - bpp] : 0;
      const b = y > 0 ? pixels[(y - 1) * stride + x] : 0;
      const c = x >= bpp && y > 0 ? pixels[(y - 1) * stride + x - bpp] : 0;
      const p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
      const paeth = pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
      const predictor = [0, a, b, (a + b) >> 1, paeth][filter];
      pixels[y * stride + x] = (cur + predictor) & 0xff;
    }
  }
  const image = { width, height, channels, pixels };
  if (bitDepth === 16) {
    image.depth16 = new Uint16Array(width * height);
    for (let i = 0; i < width * height; i++) image.depth16[i] = pixels.readUInt16BE(2 * i);
  }
  return image;
}

/** Longest a page may take to answer one evaluation: a hung renderer fails the run by name. */
export const EVALUATE_TIMEOUT_MS = 60_000;

/**
 * `page.evaluate(fn)`, failing after `EVALUATE_TIMEOUT_MS` instead of waiting forever (an
 * evaluation never returns from a renderer whose main thread is stuck, and Playwright has no
 * timeout of its own for it).
 */
export function evaluateWithin(page, fn, what) {
  let timer;
  const timeout = new Promise((_, reject) => {
    timer = setTimeout(() => reject(new Error(`the page did not answer within ${EVALUATE_TIMEOUT_MS / 1000} s (${what}): its renderer is stuck`)), EVALUATE_TIMEOUT_MS);
  });
  return Promise.race([page.evaluate(fn), timeout]).finally(() => clearTimeout(timer));
}

/** Settles `promise` or gives up after `ms` (closing a browser that hangs must not hang the run). */
export function within(promise, ms) {
  let timer;
  return Promise.race([promise, new Promise((resolve) => { timer = setTimeout(resolve, ms); })]).finally(() => clearTimeout(timer));
}

export async function waitFor(page, what, predicate, timeoutMs) {
  const deadline = Date.now() + timeoutMs;
  for (;;) {
    const status = await evaluateWithin(page, () => window.webfusion?.status ?? null, `waiting for ${what}`);
    if (status && predicate(status)) return status;
    if (status?.state === 'error') throw new Error(`the page reported an error while waiting for ${what}: ${status.message}`);
    if (Date.now() > deadline) throw new Error(`timed out waiting for ${what}; last status ${JSON.stringify(status)}`);
    await new Promise((r) => setTimeout(r, 250));
  }
}

