%% @doc The colour detector's datagrams as a sensor device (SPEC §7).
%%
%% Each datagram is one JSON object, `{"color": "red" | "blue", "x": int,
%% "y": int, "area": int, "t": int}' (x, y in pixels from the frame centre)
%% or `{"color": "red" | "blue", "none": true}'. A valid one emits
%% `{send, #{update_red => {X, Y}}}' or `none' for red, the same on
%% `update_trq' for blue. Other keys are ignored; `area' and `t', when
%% present, must be integers.
%%
%% Anything else is dropped and counted by reason, with a logger warning
%% naming the device at most once a second: `oversized' (longer than
%% `max_datagram'), `not_json', `not_object', `no_colour',
%% `unknown_colour', `bad_field' (x or y missing, not integers or beyond
%% ±1048576, a non-integer area or t, `none' not a boolean),
%% `not_allowed' (a sender outside `allow').
%%
%% Options: `port' (default 0: an ephemeral port, read it from `info'), `ip'
%% (bind address, default `{127,0,0,1}'), `allow' (sender addresses,
%% default `any'), `max_datagram' (default 1024 bytes), `recbuf' (the
%% socket's kernel receive buffer, default 1 MiB).
%%
%% `info/2' (under `device' in `toroco:inspect(Name)'): `port' (the actual
%% port), `ip', `accepted', `rejected', `rejected_by' (counts by reason),
%% `max_datagram'.
-module(toroco_udp_camera).
-behaviour(toroco_device).

-export([stimulus/2]).
-export([interface/1, init/2, handle_input/4, handle_event/4, info/2, terminate/3]).

%% @doc Lockstep (SPEC §14): a datagram for camera device `Device', as a
%% stimulus for `toroco_clock:tick/2', checked and decoded exactly as one
%% that came over UDP from the loopback address.
-spec stimulus(atom(), binary()) -> toroco_clock:stimulus().
stimulus(Device, Datagram) ->
    {Device, {?MODULE, datagram, Datagram}}.

-define(COORD_MAX, 1048576).
-define(INT_MAX, 9223372036854775807).

-spec interface(map()) -> #{inputs := [], outputs := [update_red | update_trq]}.
interface(_Opts) ->
    #{inputs => [], outputs => [update_red, update_trq]}.

-spec init(atom(), map()) -> {ok, receiving, map()} | {error, term()}.
init(Name, Opts) ->
    Allowed = [port, ip, allow, max_datagram, recbuf],
    case [K || K <- maps:keys(Opts), not lists:member(K, Allowed)] of
        [K | _] -> {error, {unknown_option, K}};
        [] -> open(Name, Opts)
    end.

open(Name, Opts) ->
    Specs = [{port, {port, 0}}, {ip, {ip, {127, 0, 0, 1}}}, {allow, {allow, any}},
             {max_datagram, {pos_integer, 1024}}, {recbuf, {pos_integer, 1048576}}],
    case toroco_net:options(Specs, Opts) of
        {ok, #{port := Port, ip := Ip, allow := Allow, max_datagram := Max, recbuf := RecBuf}} ->
            case toroco_net:udp_open(Ip, Port, Max, RecBuf) of
                {ok, S, Actual} ->
                    {ok, receiving, #{name => Name, socket => S, port => Actual, ip => Ip,
                                      allow => Allow, max_datagram => Max, accepted => 0,
                                      bad => toroco_bad_input:new(Name)}};
                {error, Reason} ->
                    logger:warning("~p (toroco_udp_camera) not started: ~0p", [Name, Reason],
                                   #{domain => [toroco, hw]}),
                    {error, Reason}
            end;
        Err ->
            Err
    end.

-spec handle_input(atom(), term(), receiving, map()) -> toroco_behavior:result().
handle_input(_Input, _Value, _State, _D) ->
    keep_state_and_data.

-spec handle_event(gen_statem:event_type(), term(), receiving, map()) ->
          toroco_behavior:result().
handle_event(info, {?MODULE, datagram, Data}, State, D = #{socket := S}) ->
    handle_event(info, {udp, S, {127, 0, 0, 1}, 0, Data}, State, D);
handle_event(info, {udp, S, Ip, _Port, Data}, _State, D = #{socket := S}) ->
    toroco_net:udp_datagram(Ip, Data, D, fun(Bin) ->
                                                 case sighting(Bin) of
                                                     {ok, Out, V} -> {ok, {send, #{Out => V}}};
                                                     Err -> Err
                                                 end
                                         end);
handle_event(info, {udp_passive, S}, _State, #{socket := S}) ->
    toroco_net:udp_rearm(S),
    keep_state_and_data.

-spec info(receiving, map()) -> map().
info(_State, D = #{accepted := A, bad := B}) ->
    (maps:with([port, ip, max_datagram], D))#{accepted => A,
                                              rejected => toroco_bad_input:total(B),
                                              rejected_by => toroco_bad_input:counts(B)}.

-spec terminate(term(), receiving, map()) -> ok.
terminate(_Reason, _State, #{socket := S}) ->
    gen_udp:close(S).

%%====================================================================
%% Datagrams
%%====================================================================

sighting(Data) ->
    try jiffy:decode(Data, [return_maps]) of
        M when is_map(M) -> object(M);
        _ -> {error, not_object}
    catch
        _:_ -> {error, not_json}
    end.

object(#{<<"color">> := C} = M) ->
    case colour(C) of
        {ok, Out} ->
            case M of
                #{<<"none">> := true} -> {ok, Out, none};
                #{<<"none">> := N} when N =/= false -> {error, bad_field};
                #{<<"x">> := X, <<"y">> := Y} when is_integer(X), abs(X) =< ?COORD_MAX,
                                                   is_integer(Y), abs(Y) =< ?COORD_MAX ->
                    case optional_int(<<"area">>, M) andalso optional_int(<<"t">>, M) of
                        true -> {ok, Out, {X, Y}};
                        false -> {error, bad_field}
                    end;
                #{} -> {error, bad_field}
            end;
        error ->
            {error, unknown_colour}
    end;
object(_) ->
    {error, no_colour}.

colour(<<"red">>) -> {ok, update_red};
colour(<<"blue">>) -> {ok, update_trq};
colour(_) -> error.

optional_int(Key, M) ->
    case M of
        #{Key := V} -> is_integer(V) andalso abs(V) =< ?INT_MAX;
        #{} -> true
    end.
