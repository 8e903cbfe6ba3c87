// Drives the system's chromium (headless, never a downloaded browser)
// with puppeteer-core for the Common Test suites and the screenshots:
// one JSON command per stdin line, one JSON answer per stdout line.
//   {"open": URL, "width": W, "height": H}   a new page at URL
//   {"open": URL, "fresh": true}            ... in a new browser profile (no cookies)
//   {"url": true}                           the page's address now (after redirects)
//   {"waitFor": JS, "timeout": Ms}          until the expression is truthy; its value
//   {"eval": JS}                            the expression's value
//   {"click": Selector} / {"select": Selector, "value": V} / {"type": Selector, "text": T}
//   {"screenshot": Path}
//   {"quit": true}
// Answers: {"ok": true, "value": V} or {"ok": false, "error": Why}.
'use strict';
const puppeteer = require('puppeteer-core');
const readline = require('readline');

const executablePath = process.env.TOROCO_CHROMIUM || '/usr/bin/chromium';
// More switches, a JSON array (the TLS suites' trusted test CA).
const extraArgs = JSON.parse(process.env.TOROCO_CHROMIUM_ARGS || '[]');
let browser = null, page = null, context = null;
const console_lines = [];

async function run(c) {
  if (c.open) {
    if (!browser) browser = await puppeteer.launch({ executablePath, headless: true,
      args: ['--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage', ...extraArgs] });
    if (page) await page.close();
    if (c.fresh) {
      if (context) await context.close();
      context = await browser.createBrowserContext();
      page = await context.newPage();
    } else page = await browser.newPage();
    page.on('console', (m) => console_lines.push(m.text()));
    page.on('pageerror', (e) => console_lines.push('pageerror: ' + e.message));
    await page.setViewport({ width: c.width || 1400, height: c.height || 900 });
    await page.goto(c.open, { waitUntil: 'load', timeout: 15000 });
    return null;
  }
  if (c.waitFor) {
    const h = await page.waitForFunction(c.waitFor, { timeout: c.timeout || 10000, polling: 50 });
    return await h.jsonValue();
  }
  if (c.eval) return await page.evaluate(c.eval);
  if (c.url) return page.url();
  if (c.click) { await page.click(c.click); return null; }
  if (c.select) { await page.select(c.select, c.value); return null; }
  if (c.type) { await page.$eval(c.type, (e) => { e.value = ''; }); await page.type(c.type, c.text); return null; }
  if (c.screenshot) { await page.screenshot({ path: c.screenshot }); return c.screenshot; }
  if (c.console) return console_lines.splice(0);
  if (c.quit) { if (browser) await browser.close(); process.exit(0); }
  throw new Error('unknown command ' + JSON.stringify(c));
}

const rl = readline.createInterface({ input: process.stdin });
let chain = Promise.resolve();
rl.on('line', (line) => {
  chain = chain.then(async () => {
    let answer;
    try { answer = { ok: true, value: await run(JSON.parse(line)) }; }
    catch (e) { answer = { ok: false, error: String(e && e.message || e) }; }
    process.stdout.write(JSON.stringify(answer === undefined ? null : answer) + '\n');
  });
});
rl.on('close', () => { chain.then(async () => { if (browser) await browser.close(); process.exit(0); }); });
