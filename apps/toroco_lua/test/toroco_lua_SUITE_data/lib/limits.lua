local M = {}
function M.spin() while true do end end
function M.hoard()
  local keep = {}
  for i = 1, 1e9 do keep[i] = string.rep('x', 100) .. i end
end
-- one C call that backtracks for ages: the budget cannot see inside it
function M.backtrack()
  return string.find(string.rep('a', 5000), string.rep('a-', 10) .. 'b')
end
return M
