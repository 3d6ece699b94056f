// Bundles the report front-end into one IIFE script and one stylesheet:
//   node build.mjs OUTDIR      (or LOOPSFM_REPORT_BUNDLE_DIR=OUTDIR node build.mjs)
// writes OUTDIR/report.js and OUTDIR/report.css. CMake embeds both in the loopsfm binary,
// so a report opens offline from file:// with no other file beside it.
import * as esbuild from 'esbuild';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const outdir = process.argv[2] || process.env.LOOPSFM_REPORT_BUNDLE_DIR;
if (!outdir) {
  console.error('usage: node build.mjs OUTDIR (or set LOOPSFM_REPORT_BUNDLE_DIR)');
  process.exit(2);
}

const common = { bundle: true, minify: true, legalComments: 'none', logLevel: 'warning' };
await esbuild.build({
  ...common,
  entryPoints: [path.join(here, 'src', 'app.js')],
  outfile: path.join(outdir, 'report.js'),
  format: 'iife',
  platform: 'browser',
  target: ['es2020'],
  // esbuild writes "</script" in strings as "<\/script" (its default for the browser), so the
  // bundle can be inlined in a <script> tag; the CMake embedding step checks it.
});
await esbuild.build({
  ...common,
  entryPoints: [path.join(here, 'src', 'report.css')],
  outfile: path.join(outdir, 'report.css'),
});
