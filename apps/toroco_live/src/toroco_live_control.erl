%% @doc The dashboard's controls (SPEC §11): suspend, resume, reset and
%% restart a behavior, inject a value into a source, load a wiring file
%% present on the node. The same JSON requests come as the body of `POST
%% /api/control' or as WebSocket frames; both go through {@link run/3}.
%%
%% A request is a JSON object with an `action':
%% <table>
%% <tr><th>action</th><th>other fields</th><th>does</th></tr>
%% <tr><td>`suspend', `resume'</td><td>`name'</td><td>`toroco:suspend_behavior/1', `resume_behavior/1'</td></tr>
%% <tr><td>`reset'</td><td>`name'</td><td>Brooks' reset: the behavior starts again from `init/1'</td></tr>
%% <tr><td>`restart'</td><td>`name'</td><td>kills the behavior's process; its supervisor restarts it (counted)</td></tr>
%% <tr><td>`inject'</td><td>`source' `[Emitter, Output]', `term' (an Erlang literal),
%%     optional `latch' (true) or `hold' (ms or "infinity")</td><td>`toroco:inject/2,3'</td></tr>
%% <tr><td>`load_wiring'</td><td>`file' (a path on the node)</td><td>`toroco:load_wiring/1'</td></tr>
%% </table>
%%
%% Nothing here creates an atom: a name that is not an existing atom is an
%% unknown name. A refused request changes nothing and says why: `{error,
%% Status, Reason, Message}' with the HTTP status it maps to.
-module(toroco_live_control).

-export([run/3, decode/2, too_large/2]).

%% The event path's messages, as the runtime defines them.

-export_type([result/0]).

-type result() :: {ok, jiffy:json_value()}
                | {error, 400 | 401 | 404 | 409 | 413, atom(), binary()}.

%% @doc Decodes a request body: a JSON object no longer than `Max' bytes.
-spec decode(binary(), pos_integer()) -> {ok, map()} | result().
decode(Body, Max) when byte_size(Body) > Max ->
    too_large(byte_size(Body), Max);
decode(Body, _Max) ->
    try jiffy:decode(Body, [return_maps]) of
        #{} = Map -> {ok, Map};
        _ -> error(400, bad_json, "the request must be a JSON object", [])
    catch
        throw:{error, Why} ->
            error(400, bad_json, "the request is not valid JSON: ~0p", [Why]);
        error:Why ->
            error(400, bad_json, "the request is not valid JSON: ~0p", [Why])
    end.

%% @doc The refusal of a request of `Size' bytes over the limit `Max'.
-spec too_large(non_neg_integer(), pos_integer()) -> result().
too_large(Size, Max) ->
    error(413, too_large, "the request is ~b bytes; the limit is ~b", [Size, Max]).

%% @doc Runs one control request if `Authorized' (the request carried the
%% dashboard's token).
-spec run(boolean(), binary() | map(), pos_integer()) -> result().
run(false, _Request, _Max) ->
    error(401, unauthorized, "controls need the dashboard's token "
          "(Authorization: Bearer T, or open the page once with ?token=T); "
          "without it the dashboard is read-only", []);
run(true, Body, Max) when is_binary(Body) ->
    case decode(Body, Max) of
        {ok, Map} -> run(true, Map, Max);
        Error -> Error
    end;
run(true, #{<<"action">> := Action} = Req, _Max) ->
    try action(Action, Req)
    catch throw:{refused, Status, Reason, Message} -> {error, Status, Reason, Message}
    end;
run(true, #{}, _Max) ->
    error(400, bad_request, "the request has no \"action\"", []).

action(A, #{<<"name">> := Name}) when A =:= <<"suspend">>; A =:= <<"resume">>;
                                     A =:= <<"reset">>; A =:= <<"restart">> ->
    B = behavior(Name),
    done(case A of
             <<"suspend">> -> toroco:suspend_behavior(B);
             <<"resume">> -> toroco:resume_behavior(B);
             <<"reset">> -> reset(B);
             <<"restart">> -> restart(B)
         end);
action(<<"inject">>, #{<<"source">> := [E, O], <<"term">> := Text} = Req) ->
    Src = {known(E, emitter), known(O, output)},
    Value = case toroco_rec_json:parse_term(Text) of
                {ok, V} -> V;
                {error, {bad_term, Why}} ->
                    refuse(400, bad_term, "\"term\" must be an Erlang literal: ~ts", [Why])
            end,
    done(case inject_opts(Req) of
             none -> toroco:inject(Src, Value);
             Opts -> toroco:inject(Src, Value, Opts)
         end);
action(<<"load_wiring">>, #{<<"file">> := File}) when is_binary(File) ->
    done(toroco:load_wiring(unicode:characters_to_list(File)));
action(A, _Req) when A =:= <<"suspend">>; A =:= <<"resume">>; A =:= <<"reset">>;
                     A =:= <<"restart">> ->
    refuse(400, bad_request, "~ts needs \"name\"", [A]);
action(<<"inject">>, _Req) ->
    refuse(400, bad_request, "inject needs \"source\": [Emitter, Output] and \"term\"", []);
action(<<"load_wiring">>, _Req) ->
    refuse(400, bad_request, "load_wiring needs \"file\", a path on the node", []);
action(A, _Req) ->
    refuse(400, unknown_action, "unknown action ~ts; one of suspend, resume, reset, restart, "
           "inject, load_wiring", [toroco_rec_json:term_text(A)]).

inject_opts(#{<<"latch">> := true}) -> #{latch => true};
inject_opts(#{<<"hold">> := <<"infinity">>}) -> #{hold => infinity};
inject_opts(#{<<"hold">> := Ms}) when is_integer(Ms), Ms >= 0 -> #{hold => Ms};
inject_opts(#{<<"hold">> := _}) -> refuse(400, bad_request, "\"hold\" is ms or \"infinity\"", []);
inject_opts(#{}) -> none.

%% A behavior's name: an existing atom naming a behavior of the robot.
behavior(Name) ->
    B = known(Name, behavior),
    case lists:member(B, maps:get(behaviors, toroco:inspect(), [])) of
        true -> B;
        false -> refuse(404, unknown_behavior, "no behavior named ~ts", [printable(Name)])
    end.

known(Name, What) when is_binary(Name) ->
    try binary_to_existing_atom(Name, utf8)
    catch error:badarg -> refuse(404, list_to_atom("unknown_" ++ atom_to_list(What)),
                                 "no ~s named ~ts", [What, printable(Name)])
    end;
known(Other, What) ->
    refuse(400, bad_request, "~s must be a string, not ~ts", [What, printable(Other)]).

printable(B) when is_binary(B) -> [$", B, $"];
printable(T) -> toroco_rec_json:term_text(T).

%% Brooks' reset (SPEC §4) and a restart through the layer's supervisor,
%% wherever the behavior runs.
reset(B) ->
    toroco:reset_behavior(B).

restart(B) ->
    toroco:restart_behavior(B).

done(ok) ->
    {ok, #{<<"ok">> => true}};
done({error, Reason}) ->
    error(409, refused, "the runtime refused: ~0tp", [Reason]).

error(Status, Reason, Fmt, Args) ->
    {error, Status, Reason, unicode:characters_to_binary(io_lib:format(Fmt, Args))}.

-spec refuse(400 | 401 | 404 | 409 | 413, atom(), io:format(), [term()]) -> no_return().
refuse(Status, Reason, Fmt, Args) ->
    {error, Status, Reason, Message} = error(Status, Reason, Fmt, Args),
    throw({refused, Status, Reason, Message}).
