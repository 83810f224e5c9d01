// Static file server with HTTP Range support (for Foxglove's remote-file reader), loopback only.
const http = require("http"), fs = require("fs"), path = require("path");
const root = process.argv[2], port = Number(process.argv[3] || 8123);
const types = { ".html": "text/html", ".js": "text/javascript", ".json": "application/json", ".wasm": "application/wasm", ".png": "image/png", ".ttf": "font/ttf" };
http.createServer((req, res) => {
  let u = decodeURIComponent(new URL(req.url, "http://x").pathname); if (u.endsWith("/")) u += "index.html"; const p = path.join(root, u);
  fs.stat(p, (err, st) => {
    if (err || !st.isFile()) { res.writeHead(404); return res.end(); }
    const h = { "Content-Type": types[path.extname(p)] || "application/octet-stream", "Accept-Ranges": "bytes", "Access-Control-Allow-Origin": "*" };
    const m = /bytes=(\d*)-(\d*)/.exec(req.headers.range || "");
    if (m) {
      const start = m[1] ? Number(m[1]) : st.size - Number(m[2]);
      const end = m[1] && m[2] ? Math.min(Number(m[2]), st.size - 1) : st.size - 1;
      res.writeHead(206, { ...h, "Content-Range": `bytes ${start}-${end}/${st.size}`, "Content-Length": end - start + 1 });
      return fs.createReadStream(p, { start, end }).pipe(res);
    }
    res.writeHead(200, { ...h, "Content-Length": st.size });
    fs.createReadStream(p).pipe(res);
  });
}).listen(port, "127.0.0.1");
