%% Helpers shared by the suites that run the pru_port program's sim
%% backend: the program built, and the servos' PWM on a fake sysfs tree.
-module(toroco_hw_test_lib).
-export([require_pru_port/1, fake_pwm/3, pwm/3]).

%% For `init_per_suite': `Config' with `{exe, Path}', or the suite fails
%% saying how to build the program.
require_pru_port(Config) ->
    Exe = filename:join(code:priv_dir(toroco_hw), "pru_port"),
    case filelib:is_regular(Exe) of
        true -> [{exe, Exe} | Config];
        false -> {fail, {not_built, Exe, "run make -C c_src/pru_port"}}
    end.

%% Channel `Ch' of PWM chip `Chip' under the fake sysfs `Root', exported
%% and all zero.
fake_pwm(Root, Chip, Ch) ->
    ChipDir = filename:join(Root, "class/pwm/pwmchip" ++ integer_to_list(Chip)),
    Dir = filename:join(ChipDir, "pwm" ++ integer_to_list(Ch)),
    ok = filelib:ensure_dir(filename:join(Dir, "x")),
    ok = file:write_file(filename:join(ChipDir, "export"), ""),
    [ok = file:write_file(filename:join(Dir, F), "0\n") || F <- ["period", "duty_cycle", "enable"]],
    ok.

%% What attribute `Attr' of chip 0's channel `Ch' holds. The program
%% rewrites a file in place (truncate, then write), as sysfs is written; a
%% read between the two sees it empty, which a real sysfs file never is:
%% read again then.
pwm(Root, Ch, Attr) ->
    pwm(Root, Ch, Attr, 100).

pwm(Root, Ch, Attr, Tries) ->
    Path = filename:join([Root, "class/pwm/pwmchip0", "pwm" ++ integer_to_list(Ch), Attr]),
    {ok, Bin} = file:read_file(Path),
    case string:trim(binary_to_list(Bin)) of
        "" when Tries > 1 -> pwm(Root, Ch, Attr, Tries - 1);
        Value -> Value
    end.
