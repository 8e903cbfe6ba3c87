%% @doc What the dashboard shows, read from the runtime: `toroco:inspect/0,1'
%% for every name, plus each process's restarts, mailbox and state. Every
%% term becomes JSON through `toroco_rec_json', and every value a person
%% may want back carries both `value' and `term'.
%%
%% {@link api/0} is the body of `GET /api/state' (inspect/0 and inspect/1
%% as they are); {@link page/2} is the state frame the page draws, shaped
%% for drawing (lists in priority order, sources as `[Emitter, Output]').
%% {@link readings/0} is the raw reading both are made from, also used by
%% `toroco_live_metrics'; {@link patch/2} brings a reading up to date with
%% one event of the observer tap (winners, holds, latches, last values,
%% output latches, status and restarts), so that the dashboard reads the
%% runtime itself only for what events do not carry (the wiring's shape,
%% mailboxes, states, device counters).
-module(toroco_live_state).

-export([api/0, page/1, page/2, readings/0, patch/2]).

-export_type([node_reading/0, rates/0, reading/0]).

-type node_reading() :: #{name := atom(), info := map(), restarts := non_neg_integer(),
                          mailbox := non_neg_integer() | null, state := term()}.
%% Events per second: per source (`{Emitter, Output}', what it emitted) and
%% per input (`{Receiver, Input}', what was delivered).
-type rates() :: #{emits := #{{atom(), atom()} => number()},
                   delivers := #{{atom(), atom()} => number()}}.

%% A reading of the whole robot: inspect/0, and a node reading per name in
%% its order.
-type reading() :: {map(), [node_reading()]}.

%% Longest term text shown for a state.
-define(STATE_TEXT, 300).

%% @doc `GET /api/state': `{"inspect": inspect(), "nodes": {Name: inspect(Name)},
%% "rosbridge_clients": [Client]}', a client as `toroco_live:rosbridge_clients/0'
%% says (SPEC §15, client mode).
-spec api() -> jiffy:json_value().
api() ->
    Overview = toroco:inspect(),
    Names = names(Overview),
    Nodes = [{N, toroco:inspect(N)} || N <- Names],
    Clients = [C#{last_error := toroco_rec_json:term_text(E)}
               || #{last_error := E} = C <- toroco_live:rosbridge_clients()],
    toroco_rec_json:value(#{inspect => Overview,
                             nodes => maps:from_list([{N, I} || {N, I} <- Nodes, is_map(I)]),
                             rosbridge_clients => Clients}).

%% @doc Every behavior and device with what the page and the metrics need.
-spec readings() -> {map(), [node_reading()]}.
readings() ->
    Overview = toroco:inspect(),
    {Overview, [reading(N) || N <- names(Overview)]}.

names(#{behaviors := Bs, devices := Ds}) -> Bs ++ Ds.

reading(Name) ->
    Info = case toroco:inspect(Name) of
               #{} = I -> I;
               {error, _} -> #{name => Name, status => down}
           end,
    %% what the behavior's own process told inspect/1, on whatever node
    Process = maps:get(process, Info, #{}),
    #{name => Name, info => maps:without([process], Info), restarts => maps:get(restarts, Info, 0),
      mailbox => maps:get(mailbox, Process, null),
      state => case Process of
                   #{state := S} -> {value, S};
                   #{} -> down
               end}.

%% @doc The page's state frame, read now.
-spec page(rates()) -> jiffy:json_value().
page(Rates) ->
    page(Rates, readings()).

%% @doc The page's state frame from a reading.
-spec page(rates(), reading()) -> jiffy:json_value().
page(Rates, {Overview, Readings}) ->
    #{<<"type">> => <<"state">>,
      <<"node">> => toroco_rec_json:value(node()),
      <<"t">> => erlang:system_time(millisecond),
      <<"layers">> => layers(Overview),
      <<"removed_layers">> => toroco_rec_json:value(maps:get(removed_layers, Overview, [])),
      <<"nodes">> => [node_json(R, Rates) || R <- Readings]}.

layers(#{layers := Layers}) ->
    [#{<<"layer">> => L, <<"names">> => toroco_rec_json:value(Ns)}
     || {L, Ns} <- lists:reverse(lists:sort(maps:to_list(Layers)))].

node_json(#{name := N, info := Info, restarts := R, mailbox := Q, state := S}, Rates) ->
    Base = #{<<"name">> => toroco_rec_json:value(N),
             <<"kind">> => toroco_rec_json:value(maps:get(kind, Info, unknown)),
             <<"module">> => toroco_rec_json:value(maps:get(module, Info, unknown)),
             <<"layer">> => toroco_rec_json:value(maps:get(layer, Info, 0)),
             <<"status">> => toroco_rec_json:value(maps:get(status, Info, down)),
             <<"restarts">> => R,
             <<"mailbox">> => Q,
             <<"state">> => state_json(S),
             <<"inputs">> => [input_json(N, I, In, Rates)
                              || {I, In} <- lists:sort(maps:to_list(maps:get(inputs, Info, #{})))],
             <<"outputs">> => [output_json(N, O, Out, Rates)
                               || {O, Out} <- lists:sort(maps:to_list(maps:get(outputs, Info, #{})))],
             <<"reset">> => [src(Src) || Src <- maps:get(reset, Info, [])]},
    case Info of
        #{device := Counters} -> Base#{<<"device">> => toroco_rec_json:value(texts(Counters))};
        #{} -> Base
    end.

state_json({value, S}) ->
    Text = toroco_rec_json:term_text(S),
    #{<<"term">> => case byte_size(Text) > ?STATE_TEXT of
                        true -> <<(binary:part(Text, 0, ?STATE_TEXT))/binary, "...">>;
                        false -> Text
                    end};
state_json(Other) ->
    #{<<"term">> => null, <<"note">> => toroco_rec_json:value(Other)}.

input_json(N, I, In, #{emits := Emits, delivers := Delivers}) ->
    Sources = maps:get(sources, In, []),
    #{<<"input">> => toroco_rec_json:value(I),
      <<"sources">> => [#{<<"source">> => src(S), <<"priority">> => P,
                          <<"rate">> => maps:get(S, Emits, 0)}
                        || {P, S} <- lists:zip(lists:seq(1, length(Sources)), Sources)],
      <<"winner">> => src(maps:get(winner, In, none)),
      <<"holds">> => [#{<<"source">> => src(S), <<"ms">> => toroco_rec_json:value(Ms)}
                      || {S, Ms} <- maps:get(holds, In, [])],
      <<"latches">> => [(toroco_rec_json:carry(V))#{<<"source">> => src(S)}
                        || {S, V} <- maps:get(latches, In, [])],
      <<"last">> => case maps:get(last, In, none) of
                        {value, V} -> toroco_rec_json:carry(V);
                        none -> null
                    end,
      <<"rate">> => maps:get({N, I}, Delivers, 0)}.

output_json(N, O, Out, #{emits := Emits}) ->
    #{<<"output">> => toroco_rec_json:value(O),
      <<"inhibited">> => maps:get(inhibited, Out, false),
      <<"inhibitors">> => [src(S) || S <- maps:get(inhibitors, Out, [])],
      <<"latch">> => case maps:get(latch, Out, none) of
                         {value, V} -> toroco_rec_json:carry(V);
                         none -> null
                     end,
      <<"rate">> => maps:get({N, O}, Emits, 0)}.

src(none) -> null;
src({E, O}) -> [toroco_rec_json:value(E), toroco_rec_json:value(O)].

%% @doc A reading brought up to date with one event of the observer tap
%% (SPEC §10). Events about names the reading does not have change nothing:
%% the next reading brings them.
-spec patch(term(), reading()) -> reading().
patch({router, _T, {R, I}, View}, Reading) ->
    input(R, I, fun(In) -> maps:merge(In, maps:with([winner, holds, latches], View)) end, Reading);
patch({deliver, _T, {R, I}, V}, Reading) ->
    input(R, I, fun(In) -> In#{last => {value, V}} end, Reading);
patch({emit, _T, {E, O}, Kind, V}, Reading) ->
    Latch = case Kind of set -> {value, V}; _ -> none end,
    node(E, fun(N = #{info := Info = #{outputs := #{O := Out} = Outs}}) ->
                    N#{info := Info#{outputs := Outs#{O := Out#{latch => Latch}}}};
               (N) -> N
            end, Reading);
patch({lifecycle, _T, Name, What}, Reading) ->
    node(Name, fun(N = #{info := Info, restarts := R}) ->
                       case What of
                           suspended -> N#{info := Info#{status => suspended}};
                           resumed -> N#{info := Info#{status => running}};
                           started -> N#{info := Info#{status => running}};
                           restarted -> N#{info := Info#{status => running}, restarts := R + 1};
                           stopped -> N#{info := Info#{status => down}};
                           _ -> N
                       end
               end, Reading);
patch(_Event, Reading) ->
    Reading.

input(R, I, Fun, Reading) ->
    node(R, fun(N = #{info := Info = #{inputs := #{I := In} = Ins}}) ->
                    N#{info := Info#{inputs := Ins#{I := Fun(In)}}};
               (N) -> N
            end, Reading).

node(Name, Fun, {Overview, Readings}) ->
    {Overview, [case N of
                    #{name := Name} -> Fun(N);
                    _ -> N
                end || N <- Readings]}.

%% A device's counters name paths and addresses as strings (the motors'
%% `sysfs_root'): the page shows them as text, not as lists of codes.
texts(M) when is_map(M) -> maps:map(fun(_, V) -> texts(V) end, M);
texts(L) when is_list(L), L =/= [] ->
    case io_lib:printable_unicode_list(L) of
        true -> unicode:characters_to_binary(L);
        false -> L
    end;
texts(V) -> V.
