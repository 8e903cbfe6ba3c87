%% @doc Lua code changing the network (SPEC §16): a `main.lua' of the
%% original Torocó turned into the node's behaviors and wiring ({@link
%% load/2}), and the wiring calls a running Lua behavior makes ({@link
%% call/3}: `load_behavior', `add_behavior' with inline functions,
%% `set_inputs', `set_inhibitors', `suspend_behavior', `resume_behavior',
%% `remove_behavior', `configure_polling' with its converter), each through
%% the runtime's API. Also where a Lua behavior's files are: its program's
%% folder ({@link root/2}) and the paths its errors name ({@link path/2},
%% {@link reason/2}).
%%
%% It sits beside `toroco_lua' (the behaviour callbacks) and
%% `toroco_lua_actions' (what an activation's answer asks the engine to do).
-module(toroco_lua_main).

-export([load/2, call/3, call_logged/4, ctx/1, reason/2, path/2, root/2]).
-export_type([ctx/0]).

%% Where a wiring call starts: the program's folder, the file of the code
%% making it, its Lua state (for inline functions) and the options of what
%% it adds.
-type ctx() :: #{root := file:filename_all(), file := file:filename_all(),
                 host := toroco_lua_port:id() | none, opts := map()}.

-define(LOG, #{domain => [toroco, lua]}).

%% @doc `toroco_lua:load_main/2': the main file runs in a Lua state of its
%% own, its wiring calls are gathered and made here in its order (a
%% converter's `configure_polling' first, so the wiring names what it
%% emits), and the state is closed once they are (it lives on while a
%% behavior it hosts does).
-spec load(file:filename_all(), toroco_lua:main_opts()) ->
          {ok, #{behaviors := [atom()]}} | {error, {file:filename_all(), non_neg_integer(), term()}}.
load(Path, Opts) ->
    Abs = filename:absname(Path),
    Limits = #{budget => maps:get(budget, Opts, toroco_lua:env(budget)),
               memory => maps:get(memory, Opts, toroco_lua:env(memory))},
    D = #{name => main, file => Path, args => #{}, id => none},
    case toroco_lua_port:open(filename:basename(Abs), filename:dirname(Abs),
                              maps:get(params, Opts, #{}), Limits, toroco_clock:now_ms()) of
        {ok, Id, _Port, Actions} ->
            _ = [toroco_lua_actions:print(Text, D) || {print, Text} <- Actions],
            Ctx = #{root => filename:dirname(Path), opts => Opts, host => Id, file => Path},
            Calls = [{Op, Line, Args} || {main, Op, Line, Args} <- Actions],
            %% converters first, so that the wiring names what they emit
            {Polling, Others} = lists:partition(
                                  fun({Op, _, _}) -> Op =:= <<"configure_polling">> end, Calls),
            Result = apply_main(Polling ++ Others, Path, Ctx, []),
            %% the state lives on while a behavior it hosts does
            _ = toroco_lua_port:close(Id),
            Result;
        {stopped, {lua_error, _, Line, Msg} = R, _} ->
            {error, {path(element(2, R), D), Line, Msg}};
        {stopped, {lua_limit, Src, What}, _} ->
            {error, {path(Src, D), 0, {lua_limit, What}}};
        {error, Why} ->
            {error, {Path, 0, Why}}
    end.

apply_main([], _Path, _Ctx, Loaded) ->
    {ok, #{behaviors => lists:reverse(Loaded)}};
apply_main([{Op, Line, Args} | Rest], Path, Ctx, Loaded) ->
    case call(Op, Args, Ctx) of
        ok -> apply_main(Rest, Path, Ctx, Loaded);
        {loaded, Name} -> apply_main(Rest, Path, Ctx, [Name | Loaded]);
        {error, Why} -> {error, {Path, Line, Why}}
    end.

%% @doc One wiring call of Lua code (main.lua, or a behavior changing the
%% network); paths start at the program's folder `root'.
-spec call(binary(), list(), ctx()) -> ok | {loaded, atom()} | {error, term()}.
call(<<"load_behavior">>, [Name, File, Params], #{root := Root, opts := Opts}) ->
    B = binary_to_atom(Name),
    Layer = maps:get(B, maps:get(layers, Opts, #{}), 0),
    Limits = maps:with([budget, memory, layers], Opts),
    case toroco_lua:add_behavior(B, Limits#{file => lua_file(Root, File), root => Root,
                                            layer => Layer, params => table(Params)}) of
        ok -> {loaded, B};
        Error -> Error
    end;
call(<<"add_behavior">>, [Name, Slot], Ctx = #{root := Root, opts := Opts, host := Host}) ->
    B = binary_to_atom(Name),
    Layer = maps:get(B, maps:get(layers, Opts, #{}), 0),
    Limits = maps:with([budget, memory, layers], Opts),
    case toroco_lua:add_behavior(B, Limits#{file => maps:get(file, Ctx), root => Root,
                                            layer => Layer, host => {Host, Slot}}) of
        ok -> {loaded, B};
        Error -> Error
    end;
call(<<"set_inputs">>, [R, Inputs], _Ctx) ->
    toroco:set_inputs(binary_to_atom(R),
                      maps:from_list([{binary_to_atom(I), lists:reverse(sources(Ss))}
                                      || {I, Ss} <- maps:to_list(table(Inputs))]));
call(<<"set_inhibitors">>, [E, Outputs], _Ctx) ->
    toroco:set_inhibitors(binary_to_atom(E),
                          maps:from_list([{binary_to_atom(O), sources(Ss)}
                                          || {O, Ss} <- maps:to_list(table(Outputs))]));
call(<<"suspend_behavior">>, [B], _Ctx) -> toroco:suspend_behavior(binary_to_atom(B));
call(<<"resume_behavior">>, [B], _Ctx) -> toroco:resume_behavior(binary_to_atom(B));
call(<<"remove_behavior">>, [B], _Ctx) -> toroco:remove_behavior(binary_to_atom(B));
call(<<"configure_polling">>, [D, E, Ms, false], _Ctx) ->
    configure_polling(D, E, Ms);
call(<<"configure_polling">>, [D, E, Ms, Slot], Ctx) ->
    case configure_polling(D, E, Ms) of
        ok -> converter(binary_to_atom(D), binary_to_atom(E), Slot, Ctx);
        Error -> Error
    end;
call(<<"run">>, _, _Ctx) -> ok;
call(Op, Args, _Ctx) -> {error, {bad_main_call, {Op, Args}}}.

sources(Ss) -> [converted({binary_to_atom(E), binary_to_atom(O)}) || [E, O] <- Ss].

%% The behavior named `'D.E'', when there is one, stands for source `{D,
%% E}': a converter (below), or a device's output under the name the
%% original gave it (torobot's `camera.update').
converted({D, E} = Src) ->
    Conv = converter_name(D, E),
    case toroco:inspect(Conv) of
        #{kind := behavior} -> {Conv, E};
        _ -> Src
    end.

%% The behavior that runs the converter of source `{D, E}': `'D.E'', in the
%% Lua state of the code that configured it, between the device and those
%% wired to `device.D.E' by Lua code, in layer 0.
converter_name(D, E) ->
    binary_to_atom(<<(atom_to_binary(D))/binary, ".", (atom_to_binary(E))/binary>>).

converter(D, E, Slot, Ctx = #{root := Root, opts := Opts, host := Host}) ->
    Conv = converter_name(D, E),
    _ = case toroco:inspect(Conv) of
            #{kind := behavior, module := toroco_lua} -> toroco:remove_behavior(Conv);
            _ -> ok
        end,
    Limits = maps:with([budget, memory], Opts),
    case toroco_lua:add_behavior(Conv, Limits#{file => maps:get(file, Ctx), root => Root,
                                               layer => 0, host => {Host, Slot},
                                               inputs => [E], outputs => [E]}) of
        ok -> toroco:set_inputs(Conv, #{E => [{D, E}]});
        Error -> Error
    end.

%% configure_polling(device.D.E, seconds): D must be a device on the node
%% with output E; one that can be polled (toroco_poll_sensor) is asked to
%% poll every Ms, one that emits by itself answers unknown_call and is left
%% as it is.
configure_polling(D, E, Ms) ->
    Dev = binary_to_atom(D),
    Out = binary_to_atom(E),
    case toroco:inspect(Dev) of
        #{kind := device, outputs := #{Out := _}} ->
            try toroco_device:call(Dev, {toroco_poll, every_ms, Ms}, 5000) of
                ok -> ok;
                {error, {unknown_call, _}} -> ok;
                {error, _} = Error -> Error
            catch exit:Why -> {error, {Dev, Why}}
            end;
        #{kind := device} -> {error, {unknown_output, {Dev, Out}}};
        #{} -> {error, {not_a_device, Dev}};
        {error, _} = Error -> Error
    end.

%% An empty Lua table crosses as [] (SPEC §16); as a set of keys it is #{}.
table([]) -> #{};
table(M) when is_map(M) -> M.

%% `path' or `path.lua', relative to `Dir'.
lua_file(Dir, File) ->
    P = filename:join(Dir, unicode:characters_to_list(File)),
    case filename:extension(P) =:= ".lua" orelse filelib:is_regular(P) of
        true -> P;
        false -> P ++ ".lua"
    end.

%% @doc The context of a wiring call a behavior makes: its program's
%% folder, its file, its Lua state and the limits of what it adds.
-spec ctx(map()) -> ctx().
ctx(D = #{file := File, args := Args0}) ->
    #{root => element(1, root(File, Args0)), file => File, host => toroco_lua:state_id(D),
      opts => maps:with([budget, memory, layers], Args0)}.

%% @doc A wiring call of a behavior's, refused with a warning in the log.
-spec call_logged(binary(), list(), ctx(), atom()) -> ok.
call_logged(Op, Args, Ctx, Name) ->
    case call(Op, Args, Ctx) of
        {error, Why} ->
            logger:warning("toroco_lua: ~p: ~ts refused: ~p", [Name, Op, Why], ?LOG#{name => Name});
        _ -> ok
    end.

%% @doc {lua_error, File, Line, Message}: File as the user named it for the
%% behavior's own file, else the module's path in the program's folder.
-spec reason({lua_error, binary(), integer(), term()} | {lua_limit, binary(), atom()}, map()) -> tuple().
reason({lua_error, Src, Line, Msg}, D) -> {lua_error, path(Src, D), Line, Msg};
reason({lua_limit, Src, What}, D) -> {lua_limit, path(Src, D), What}.

%% @doc A source the program names, as the user would: the behavior's own
%% file as given, another module by its path in the program's folder.
-spec path(unicode:chardata(), map()) -> file:filename_all().
path(Src, #{file := File, args := Args}) ->
    {Root, Rel} = root(File, Args),
    case unicode:characters_to_list(Src) of
        Rel -> File;
        Other -> filename:join(Root, Other)
    end.

%% @doc The program's folder and the file's path inside it; a file outside the
%% folder given is its own folder's.
-spec root(file:filename_all(), map()) -> {string(), string()}.
root(File, Args) ->
    Abs = unicode:characters_to_list(filename:absname(File)),
    Root = unicode:characters_to_list(filename:absname(maps:get(root, Args, filename:dirname(Abs)))),
    case string:prefix(Abs, Root ++ "/") of
        nomatch -> {filename:dirname(Abs), filename:basename(Abs)};
        Rel ->
            case filelib:safe_relative_path(Rel, Root) of
                unsafe -> {filename:dirname(Abs), filename:basename(Abs)};
                Safe -> {Root, Safe}
            end
    end.
