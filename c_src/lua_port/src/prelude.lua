-- The original Torocó API inside one behavior's Lua state (SPEC §16).
--
-- Run once per state, before the behavior's file, with the port's C
-- functions (C), the file's path and the behavior's params. Every task
-- (a coroutine the file returned, a trigger, the file's own body) is a Lua
-- coroutine; a task waits by yielding, and the port resumes it when its
-- input arrives or its timer fires.
--
-- A state hosts behaviors in slots: slot 0 is the file's; each
-- add_behavior with inline functions, and each configure_polling with a
-- converter, makes another, whose tasks start when its own behavior (a
-- process of its own on the Erlang side) attaches to it, and start again
-- when that behavior restarts. Each request names its slot; a task
-- belongs to the slot it started in. Timers are not kept here: each one is an
-- action for the Erlang side, which sets a gen_statem timeout and sends the
-- firing back, so a Lua behavior runs on the runtime's clock.
local C, file, params = ...

local co_create, co_resume, co_yield, co_status =
  coroutine.create, coroutine.resume, coroutine.yield, coroutine.status
local getinfo = debug.getinfo
local pairs, ipairs, type, select, unpack, tostring, error, setmetatable, rawset =
  pairs, ipairs, type, select, unpack, tostring, error, setmetatable, rawset
local floor, huge, concat, sort = math.floor, math.huge, table.concat, table.sort

local tasks = {}            -- task id -> {co, input, order, seq, timer, slot}
local next_task, order = 0, 0
local current = nil         -- the task running now
local slot = 0              -- the slot of the request being run
local slots = {}            -- slot -> {items = {...}, params = {...}} (not 0)
local next_slot = 0
local made = {}             -- triggers made in this request, not started yet
local STOP = {}             -- the error that ends a dispatch after a failure

-- ---- failures ------------------------------------------------------------

-- The innermost line of the behavior's own code on a coroutine's stack.
local function where(co)
  for level = 0, 64 do
    local info = getinfo(co, level, 'Sl')
    if not info then break end
    if info.currentline and info.currentline > 0 and info.source:sub(1, 1) == '@' then
      return info.source:sub(2), info.short_src, info.currentline
    end
  end
  return file, file, 0
end

local function fail(co, err)
  if err == STOP then error(STOP, 0) end
  local src, short, line = where(co)
  local msg = tostring(err)
  local prefix = short .. ':' .. line .. ': '
  if msg:sub(1, #prefix) == prefix then msg = msg:sub(#prefix + 1) end
  C.fail(src, line, msg)
  error(STOP, 0)
end

-- ---- tasks ---------------------------------------------------------------

local function ms(seconds)
  if type(seconds) ~= 'number' or seconds ~= seconds or seconds < 0 then
    error('bad time ' .. tostring(seconds) .. ' (seconds >= 0 expected)', 3)
  end
  if seconds == huge then return nil end
  return floor(seconds * 1000 + 0.5)
end

local function run(t, ...)
  local prev = current
  current = t
  local ok, err = co_resume(t.co, ...)
  current = prev
  if not ok then fail(t.co, err) end
  if co_status(t.co) == 'dead' then
    tasks[t.id] = nil
    if t.timer then C.cancel(t.id) end
  end
end

-- kind: 'file' (the file's body), 'coroutine' (a function it returned, or
-- sched.run's) or 'trigger'
local function spawn(kind, fn, ...)
  next_task = next_task + 1
  local args = {n = select('#', ...), ...}
  local t = {id = next_task, seq = 0, kind = kind, slot = slot}
  t.co = co_create(function() return fn(unpack(args, 1, args.n)) end)
  tasks[t.id] = t
  run(t)
  return t
end

-- Pauses the running task until `input' arrives (its values, packed) or
-- until `timeout_ms' passes (nil).
local function wait(input, timeout_ms, what)
  local t = current
  if not t then error(what .. ' outside a coroutine', 3) end
  t.input = input
  order = order + 1
  t.order = order
  if timeout_ms then
    t.seq = t.seq + 1
    t.timer = true
    C.timer(t.id, t.seq, timeout_ms)
  end
  local how, vals = co_yield()
  return how == 'input' and vals or nil
end

-- ---- descriptors ---------------------------------------------------------

local function names(kind, with_events)
  return setmetatable({}, {__index = function(self, name)
    local d = {kind = kind, name = name}
    if with_events then
      setmetatable(d, {__index = function(dd, event)
        local s = {kind = 'source', emitter_kind = kind, emitter = name, name = event}
        rawset(dd, event, s)
        return s
      end})
    end
    rawset(self, name, d)
    return d
  end})
end

local M = {}
M.input, M.output = names('input'), names('output')
M.device, M.behavior = names('device', true), names('behavior', true)
M.params = params or {}

local function input_name(i)
  if type(i) == 'table' and i.kind == 'input' then return i.name end
  if type(i) == 'string' then return i end
  error('bad input ' .. tostring(i) .. ' (input.NAME expected)', 3)
end

local function output_name(o)
  if type(o) == 'table' and o.kind == 'output' then return o.name end
  if type(o) == 'string' then return o end
  error('bad output ' .. tostring(o) .. ' (output.NAME or a name expected)', 3)
end

-- ---- the behavior API ----------------------------------------------------

function M.wait_for_input(input, timeout)
  local vals = wait(input_name(input), timeout and ms(timeout), 'wait_for_input')
  if vals then return unpack(vals, 1, vals.n) end
  return nil
end

local function start_trigger(tr)
  tr.started = true
  local name, handler = tr.input, tr.handler
  local t = spawn('trigger', function()
    while true do
      local vals = wait(name, nil, 'trigger')
      handler(name, unpack(vals, 1, vals.n))     -- the input's name, as the original
    end
  end)
  tr.task = t.id
end

-- A trigger starts at the end of the request that made it, in the slot
-- that made it, unless add_behavior took it for the behavior it adds.
function M.trigger(input, handler)
  local name = input_name(input)
  if type(handler) ~= 'function' then error('trigger: handler must be a function', 2) end
  local tr = {kind = 'trigger', input = name, handler = handler, slot = slot}
  made[#made + 1] = tr
  return tr
end

local function start_made()
  while #made > 0 do
    local now = made
    made = {}
    for _, tr in ipairs(now) do
      if not tr.started and not tr.taken then
        local prev = slot
        slot = tr.slot
        start_trigger(tr)
        slot = prev
      end
    end
  end
end

-- As the original: {v1, v2, timeout = s} holds the output's suppressions
-- and inhibitions s seconds; {release = true} ends them and sends nothing.
-- A second table {o = s} gives the holds too.
local function emit(kind, outs, holds)
  if type(outs) ~= 'table' then error(kind .. '_output: a table of outputs expected', 3) end
  for o, values in pairs(outs) do
    local name = output_name(o)
    local hold = holds and holds[o]
    if type(values) == 'table' and kind == 'send' and values.release then
      C.unset(name)
    else
      if type(values) == 'table' and values.timeout ~= nil then
        hold = hold or values.timeout
        local only = {}
        for k = 1, #values do only[k] = values[k] end
        values = only
      end
      C.emit(kind, name, values, hold and (ms(hold) or 'infinity') or nil)
    end
  end
end

function M.send_output(outs, holds) emit('send', outs, holds) end
function M.set_output(outs) emit('set', outs) end
function M.unset_output(o)
  if o == nil then C.unset() else C.unset(output_name(o)) end
end

-- The wiring calls of a main.lua (and of behaviors that change the network,
-- as the thesis' suspender and add/remove examples do): each is an action
-- {main, Op, Line, Args} that Erlang carries out, in order.
local function name_of(d, what)
  if type(d) == 'table' and (d.kind == 'behavior' or d.kind == 'device') then return d.name end
  error(what .. ': behavior.NAME or device.NAME expected, got ' .. tostring(d), 3)
end

local function source_of(s, what)
  if type(s) == 'table' and s.kind == 'source' then return {s.emitter, s.name} end
  error(what .. ': a source (device.D.E or behavior.B.E) expected, got ' .. tostring(s), 4)
end

-- One source or a list of them, as the original takes them (lowest
-- priority first: Erlang turns the list round).
local function sources_of(v, what)
  if type(v) == 'table' and v.kind == 'source' then return {source_of(v, what)} end
  if type(v) ~= 'table' then error(what .. ': a source or a list of sources expected', 3) end
  local out = {}
  for k, s in ipairs(v) do out[k] = source_of(s, what) end
  return out
end

local wired = false         -- a wiring call was made (a main file)
local function main(op, args)
  wired = true
  local info = getinfo(3, 'l')
  C.main(op, info and info.currentline or 0, args)
end

function M.load_behavior(b, path, ps)
  if type(path) ~= 'string' then error('load_behavior: a path expected', 2) end
  main('load_behavior', {name_of(b, 'load_behavior'), path, ps or {}})
end
function M.set_inputs(receiver, inputs)
  local r = name_of(receiver, 'set_inputs')
  if type(inputs) ~= 'table' then error('set_inputs: a table of inputs expected', 2) end
  local t = {}
  for i, v in pairs(inputs) do t[i] = sources_of(v, 'set_inputs') end
  main('set_inputs', {r, t})
end
function M.set_inhibitors(emitter, outputs)
  local e = name_of(emitter, 'set_inhibitors')
  if type(outputs) ~= 'table' then error('set_inhibitors: a table of outputs expected', 2) end
  local t = {}
  for o, v in pairs(outputs) do t[o] = sources_of(v, 'set_inhibitors') end
  main('set_inhibitors', {e, t})
end
for _, f in ipairs {'suspend_behavior', 'resume_behavior', 'remove_behavior'} do
  M[f] = function(b) main(f, {name_of(b, f)}) end
end
function M.run() main('run', {}) end
-- A new slot running `items' (functions and triggers, alone or in
-- tables): its tasks start when its behavior attaches.
local function new_slot(items, ps)
  local list = {}
  local function take(v)
    if type(v) == 'function' then list[#list + 1] = v
    elseif type(v) == 'table' and v.kind == 'trigger' then
      v.taken = true
      list[#list + 1] = v
    elseif type(v) == 'table' then
      for _, w in ipairs(v) do take(w) end
    else
      error('add_behavior: functions and triggers expected, got ' .. tostring(v), 4)
    end
  end
  take(items)
  next_slot = next_slot + 1
  slots[next_slot] = {items = list, params = ps or {}}
  return next_slot
end

-- add_behavior(behavior.B, {coroutines and triggers}, params): B's code
-- stays in this state, which lives while any behavior it hosts does.
function M.add_behavior(b, items, ps)
  local name = name_of(b, 'add_behavior')
  if type(items) == 'string' then
    main('load_behavior', {name, items, ps or {}})
    return
  end
  if ps ~= nil and type(ps) ~= 'table' then error('add_behavior: a table of params expected', 2) end
  main('add_behavior', {name, new_slot(items, ps)})
end
-- The source's device polled every `seconds' when it can be (Erlang asks
-- it; one that emits by itself is left as it is). A converter runs here, on
-- each reading, in a slot of its own (a behavior of its own on the Erlang
-- side, between the device and those wired to it): its return values are
-- the event's values.
function M.configure_polling(s, seconds, converter)
  if type(s) ~= 'table' or s.kind ~= 'source' or s.emitter_kind ~= 'device' then
    error('configure_polling: device.D.E expected, got ' .. tostring(s), 2)
  end
  if type(seconds) ~= 'number' or seconds <= 0 then
    error('configure_polling: a period in seconds expected, got ' .. tostring(seconds), 2)
  end
  if converter ~= nil and type(converter) ~= 'function' then
    error('configure_polling: a converter function expected, got ' .. tostring(converter), 2)
  end
  local conv = false
  if converter then
    local out = s.name
    conv = new_slot(function()
      while true do
        local vals = wait(out, nil, 'configure_polling')
        local r = {n = 0}
        local function pack(...) r = {n = select('#', ...), ...} end
        pack(converter(unpack(vals, 1, vals.n)))
        C.emit('send', out, {unpack(r, 1, r.n)}, nil)
      end
    end)
  end
  main('configure_polling', {s.emitter, s.name, math.max(1, math.floor(seconds * 1000 + 0.5)), conv})
end

local sched = {}
function sched.sleep(seconds)
  wait(nil, ms(seconds) or nil, 'sched.sleep')
end
function sched.run(fn, ...) return spawn('coroutine', fn, ...) end

-- ---- the sandbox ---------------------------------------------------------

print = function(...)
  local parts = {}
  for k = 1, select('#', ...) do parts[k] = tostring((select(k, ...))) end
  C.print(concat(parts, '\t'))
end

-- The runtime's clock only (lockstep): os.time() its seconds, os.clock()
-- the seconds since this state started, as the original's CPU clock was.
local os_time, os_date, os_difftime = os.time, os.date, os.difftime
local started = C.now()
os = {
  time = function(t) if t ~= nil then return os_time(t) end return floor(C.now() / 1000) end,
  clock = function() return (C.now() - started) / 1000 end,
  date = function(f, t) return os_date(f, t or floor(C.now() / 1000)) end,
  difftime = os_difftime,
}

-- math.random from a generator of this state's own (Park and Miller's),
-- not the C library's, which every state of the program shares: a seed
-- (math.randomseed(os.time()) on the runtime's clock) gives the same
-- numbers every run, whatever the other behaviors draw.
local rand_state = 1
local function rand_next()
  rand_state = (rand_state * 16807) % 2147483647
  return rand_state / 2147483647
end
math.randomseed = function(x)
  x = floor(tonumber(x) or 0) % 2147483646
  if x < 0 then x = x + 2147483646 end
  rand_state = x + 1
end
math.random = function(m, n)
  local r = rand_next()
  if m == nil then return r end
  if n == nil then m, n = 1, m end
  m, n = floor(m), floor(n)
  if m > n then error('bad argument to \'random\' (interval is empty)', 2) end
  return m + floor(r * (n - m + 1))
end

local loadstring_ = loadstring
loadstring = function(s, name)
  if type(s) == 'string' and s:byte(1) == 27 then return nil, 'binary chunks are refused' end
  return loadstring_(s, name)
end
string.dump = nil
for _, g in ipairs {'dofile', 'loadfile', 'load', 'module', 'package', 'debug',
                    'getfenv', 'setfenv', 'newproxy', 'io'} do
  _G[g] = nil
end

local loaded = {
  toroco = M, ['toroco.toroco'] = M, ['toroco.init'] = M,
  ['toroco.device'] = M.device, ['toroco.behavior'] = M.behavior,
  ['toroco.input'] = M.input, ['toroco.output'] = M.output,
  ['lumen.sched'] = sched,
  string = string, table = table, math = math, os = os, coroutine = coroutine,
}
require = function(name)
  if type(name) ~= 'string' then error('require: a module name expected', 2) end
  local m = loaded[name]
  if m ~= nil then return m end
  m = C.loadmodule(name)(name)
  if m == nil then m = true end
  loaded[name] = m
  return m
end

params = M.params

-- ---- entry points (called by the port) -----------------------------------

local entry = {}
local file_params = M.params

-- Each request runs one slot's tasks, with that slot's params.
local function enter(n)
  if #made > 0 then made = {} end   -- those of a request that failed never start
  if n ~= slot or n ~= 0 then
    slot = n
    local sl = slots[n]
    M.params = sl and sl.params or file_params
    params = M.params
  end
end

-- The behavior's file: its body runs as a task; the functions it returns
-- (alone or in tables) and the triggers start as tasks. A file that
-- returns nothing and starts nothing is a behavior with no tasks.
function entry.boot(chunk)
  enter(0)
  local function start(v)
    if type(v) == 'function' then spawn('coroutine', v)
    elseif type(v) == 'table' and v.kind == 'trigger' then
      if not v.started and not v.taken then start_trigger(v) end
    elseif type(v) == 'table' then
      for _, w in ipairs(v) do start(w) end
    end
  end
  spawn('file', function()
    local first = next_task
    local rets = {n = 0}
    local function pack(...) rets = {n = select('#', ...), ...} end
    pack(chunk())
    for k = 1, rets.n do start(rets[k]) end
    if rets.n == 0 and #made == 0 and next_task == first and not wired then
      C.warn(file .. ' returns nothing: a behavior with no tasks')
    end
  end)
  start_made()
end

local function by_order(a, b) return a.order < b.order end

function entry.input(n, name, ...)
  enter(n)
  local vals = {n = select('#', ...), ...}
  local ready = {}
  for _, t in pairs(tasks) do
    if t.input == name and t.slot == n then ready[#ready + 1] = t end
  end
  if #ready > 1 then sort(ready, by_order) end
  for _, t in ipairs(ready) do
    if tasks[t.id] and t.input == name then
      t.input = nil
      if t.timer then t.timer = nil; C.cancel(t.id) end
      run(t, 'input', vals)
    end
  end
  start_made()
end

function entry.timer(id, seq)
  local t = tasks[id]
  if t and t.timer and t.seq == seq then
    enter(t.slot)
    t.timer, t.input = nil, nil
    run(t, 'timeout')
    start_made()
  end
end

-- A slot's behavior attached: its tasks start (again, after a restart).
function entry.attach(n)
  local sl = slots[n]
  if not sl then return false end
  enter(n)
  for _, v in ipairs(sl.items) do
    if type(v) == 'function' then spawn('coroutine', v)
    else start_trigger({input = v.input, handler = v.handler}) end
  end
  start_made()
  return true
end

-- A slot's behavior stopped: its tasks end (timers they set do nothing).
function entry.detach(n)
  for id, t in pairs(tasks) do
    if t.slot == n then tasks[id] = nil end
  end
  return true
end

-- What the tasks wait for, for inspect: {{task, kind, input or false, timer}}
-- (one slot's, or all).
function entry.waits(n)
  local out = {}
  for id, t in pairs(tasks) do
    if n == nil or t.slot == n then
      out[#out + 1] = {id, t.kind, t.input or false, t.timer or false}
    end
  end
  sort(out, function(a, b) return a[1] < b[1] end)
  return out
end

entry.STOP = STOP
return entry
