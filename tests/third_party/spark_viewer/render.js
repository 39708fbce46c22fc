// Renders a 3DGS PLY in a real web splat viewer (Spark on three.js) in headless Chromium and saves
// the frame as a PNG: serves index.html, viewer.js, the npm packages, the model and the camera on
// 127.0.0.1 (an ephemeral port), starts Chromium on the page and waits for the page to post its
// canvas. Prints what the page logs. Exit code 0 with the PNG written; 1 when the page failed or
// timed out; 2 on bad arguments.
// Usage: node render.js NODE_MODULES_DIR CHROMIUM MODEL.ply CAMERA.json OUT.png [TIMEOUT_S]
const http = require('http');
const fs = require('fs');
const path = require('path');
const os = require('os');
const { spawn } = require('child_process');

const [modules, chromium, model, cameraFile, output, timeoutArg] = process.argv.slice(2);
if (!output) {
  console.error('usage: node render.js NODE_MODULES_DIR CHROMIUM MODEL.ply CAMERA.json OUT.png [TIMEOUT_S]');
  process.exit(2);
}
const timeoutMs = 1000 * Number(timeoutArg || 120);
const pageDir = __dirname;
const types = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript',
                '.json': 'application/json', '.wasm': 'application/wasm' };

let browser = null;
let profile = null;
function finish(code, message) {
  if (message) console.log(message);
  if (browser) browser.kill('SIGKILL');
  // Chromium's helpers may still be writing the profile for a moment: best effort.
  try { if (profile) fs.rmSync(profile, { recursive: true, force: true, maxRetries: 5 }); } catch (e) {}
  process.exit(code);
}

// A file under `root` only (no path escapes the folders served).
function serveFile(res, root, relative) {
  const file = path.resolve(root, '.' + path.posix.normalize('/' + relative));
  if (!file.startsWith(path.resolve(root) + path.sep) || !fs.existsSync(file) ||
      !fs.statSync(file).isFile()) {
    res.writeHead(404);
    res.end();
    return;
  }
  res.writeHead(200, { 'Content-Type': types[path.extname(file)] || 'application/octet-stream' });
  fs.createReadStream(file).pipe(res);
}

const requests = [];
const server = http.createServer((req, res) => {
  const url = decodeURIComponent(req.url.split('?')[0]);
  requests.push(`${req.method} ${url}`);
  if (req.method === 'POST') {
    const chunks = [];
    req.on('data', (c) => chunks.push(c));
    req.on('end', () => {
      res.writeHead(200);
      res.end();
      const body = Buffer.concat(chunks).toString();
      if (url === '/log') {
        console.log(`page: ${body}`);
        if (body.startsWith('error:')) finish(1, 'the viewer page failed');
      } else if (url === '/result') {
        const prefix = 'data:image/png;base64,';
        if (!body.startsWith(prefix)) finish(1, 'the page posted no PNG');
        fs.writeFileSync(output, Buffer.from(body.slice(prefix.length), 'base64'));
        finish(0, `wrote ${output}`);
      }
    });
    return;
  }
  if (url === '/' || url === '/index.html') return serveFile(res, pageDir, 'index.html');
  if (url === '/viewer.js') return serveFile(res, pageDir, 'viewer.js');
  if (url === '/model.ply') return serveFile(res, path.dirname(model), path.basename(model));
  if (url === '/camera.json') return serveFile(res, path.dirname(cameraFile), path.basename(cameraFile));
  if (url.startsWith('/node_modules/')) return serveFile(res, modules, url.slice('/node_modules/'.length));
  res.writeHead(404);
  res.end();
});

server.listen(0, '127.0.0.1', () => {
  const port = server.address().port;
  profile = fs.mkdtempSync(path.join(os.tmpdir(), 'mgsr-chromium-'));
  // WebGL without a GPU: ANGLE on SwiftShader (software Vulkan).
  const args = ['--headless=new', '--no-sandbox', '--disable-dev-shm-usage', '--no-first-run',
                '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist',
                `--user-data-dir=${profile}`, '--window-size=1024,1024',
                `http://127.0.0.1:${port}/index.html`];
  browser = spawn(chromium, args, { stdio: ['ignore', 'ignore', 'pipe'] });
  let stderr = '';
  // Without a desktop session Chromium complains about D-Bus on every start: not our problem.
  browser.stderr.on('data', (d) => {
    const lines = String(d).split('\n').filter((l) => l && !l.includes('dbus'));
    if (lines.length) stderr = (stderr + lines.join('\n') + '\n').slice(-4000);
  });
  browser.on('exit', (code) => {
    browser = null;
    finish(1, `chromium exited (${code}) before the page posted its frame:\n${stderr}`);
  });
  setTimeout(() => finish(1, `timed out after ${timeoutMs / 1000} s; requests: ${requests.join(', ')}\n` +
                                 `chromium: ${stderr}`), timeoutMs);
});
