const puppeteer = require("puppeteer-core");
(async () => {
  const [url, out, waitMs] = process.argv.slice(2);
  const browser = await puppeteer.launch({ executablePath: "/usr/bin/chromium", headless: true,
    args: ["--no-sandbox", "--disable-gpu", "--use-gl=swiftshader", "--enable-unsafe-swiftshader"] });
  const page = await browser.newPage();
  page.on("console", async (m) => {
    if (m.type() !== "error" && !m.text().includes("problem")) return;
    const args = await Promise.all(m.args().map((a) => a.jsonValue().catch(() => "?")));
    console.log("console:", JSON.stringify(args).slice(0, 400));
  });
  page.on("response", (r) => { if (r.status() >= 400) console.log("HTTP", r.status(), r.url()); });
  page.on("workercreated", (w) => console.log("worker", w.url()));
  page.on("pageerror", (e) => console.log("pageerror:", String(e).slice(0, 300)));
  await page.setViewport({ width: 1400, height: 860 });
  await page.goto(url, { waitUntil: "load", timeout: 120000 });
  await new Promise((r) => setTimeout(r, Number(waitMs || 20000)));
  await page.screenshot({ path: out });
  await browser.close();
})();
