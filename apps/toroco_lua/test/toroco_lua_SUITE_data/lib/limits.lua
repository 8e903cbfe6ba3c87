local M = {}
function M.spin() while true do end end
function M.hoard()
  local keep = {}
  for i = 1, 1e9 do keep[i] = string.rep('x', 100) .. i end
end
return M
