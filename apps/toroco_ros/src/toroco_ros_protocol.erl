%% @doc The rosbridge v2 protocol (RobotWebTools `ROSBRIDGE_PROTOCOL.md'),
%% pure (but for the clock, for a `cbor-raw' message without a stamp): the
%% operations this project sends and reads, built and matched
%% here only, for the server's connections (`toroco_ros_server_conn') and
%% the client (`toroco_ros_client'). An operation is a map with an `op';
%% on the wire it is JSON text ({@link encode/1}) or, for a subscription
%% that asks for it, CBOR ({@link cbor/1}).
%%
%% | op                | built by          | sent by | read by |
%% |-------------------|-------------------|---------|---------|
%% | `advertise'       | {@link advertise/2} (id `advertise:<topic>') | client | server |
%% | `unadvertise'     | {@link unadvertise/1} | client | server |
%% | `subscribe'       | {@link subscribe/2} (id `subscribe:<topic>') | client | server |
%% | `publish'         | {@link publish/2}, {@link publish_text/2} (the message's JSON made once) | both | both |
%% | `status'          | {@link status/3}  | server  | client ({@link read/1}: a refused topic by its id) |
%% | `service_response'| {@link service_response/4} | server | - |
%% | `fragment'        | {@link fragments/3} (pieces cut at character boundaries) | server | server ({@link fragment/1}) |
%% Everything else a client sends the server reads with {@link decode/1}:
%% `{Op, Id, Fields}', the fields as JSON-decoded (binary keys).
-module(toroco_ros_protocol).

-export([advertise/2, unadvertise/1, subscribe/2, publish/2, publish_text/2, publish_raw/3,
         status/3, service_response/4, fragments/3]).
-export([encode/1, cbor/1, decode/1, read/1, fragment/1, auth_token/1, level/1]).

-export_type([op/0]).

-type op() :: #{op := atom(), atom() => term()}.

%%====================================================================
%% Building
%%====================================================================

%% @doc The client advertises `Topic' of `Type'.
-spec advertise(binary(), binary()) -> op().
advertise(Topic, Type) ->
    #{op => advertise, id => <<"advertise:", Topic/binary>>, topic => Topic, type => Type}.

-spec unadvertise(binary()) -> op().
unadvertise(Topic) ->
    #{op => unadvertise, topic => Topic}.

%% @doc The client subscribes to `Topic' of `Type'.
-spec subscribe(binary(), binary()) -> op().
subscribe(Topic, Type) ->
    #{op => subscribe, id => <<"subscribe:", Topic/binary>>, topic => Topic, type => Type}.

-spec publish(binary(), map()) -> op().
publish(Topic, Msg) ->
    #{op => publish, topic => Topic, msg => Msg}.

%% @doc A publish as JSON text around a message already JSON (encoded once
%% for every subscriber).
-spec publish_text(binary(), iodata()) -> binary().
publish_text(Topic, Json) ->
    iolist_to_binary([<<"{\"op\":\"publish\",\"topic\":">>, jiffy:encode(Topic),
                      <<",\"msg\":">>, Json, $}]).

%% @doc A publish for `cbor-raw' (as rosbridge does for ROS 2): the
%% message's CDR bytes (`toroco_ros_msgs:cdr/2') and its stamp, or now.
-spec publish_raw(binary(), binary(), map()) -> {ok, op()} | {error, term()}.
publish_raw(Topic, Type, Msg) ->
    #{sec := Sec, nanosec := Nsec} =
        case Msg of
            #{header := #{stamp := Stamp}} -> Stamp;
            #{} -> toroco_ros_topics:stamp(erlang:system_time(nanosecond))
        end,
    case toroco_ros_msgs:cdr(Type, Msg) of
        {ok, Cdr} -> {ok, publish(Topic, #{bytes => {bytes, Cdr}, secs => Sec, nsecs => Nsec})};
        {error, _} = E -> E
    end.

%% @doc A status of `Level' about operation `Id' (`null': none).
-spec status(info | warning | error, term(), iodata()) -> op().
status(Level, Id, Msg) ->
    Base = #{op => status, level => Level, msg => iolist_to_binary(Msg)},
    case Id of
        null -> Base;
        _ -> Base#{id => Id}
    end.

-spec service_response(term(), binary(), term(), boolean()) -> op().
service_response(Id, Service, Values, Result) ->
    #{op => service_response, id => Id, service => Service, values => Values, result => Result}.

%% @doc A JSON text in `fragment' operations of id `Id', each piece at most
%% `Size' bytes but cut at a character boundary, so that each is a JSON
%% string (at least one character, even if longer than `Size').
-spec fragments(binary(), pos_integer(), binary()) -> [op()].
fragments(Text, Size, Id) ->
    Pieces = pieces(Text, Size, []),
    Total = length(Pieces),
    [#{op => fragment, id => Id, data => P, num => Num, total => Total}
     || {Num, P} <- lists:zip(lists:seq(0, Total - 1), Pieces)].

pieces(<<>>, _Size, Acc) -> lists:reverse(Acc);
pieces(Text, Size, Acc) when byte_size(Text) =< Size -> lists:reverse([Text | Acc]);
pieces(Text, Size, Acc) ->
    Cut = boundary(Text, Size),
    <<P:Cut/binary, Rest/binary>> = Text,
    pieces(Rest, Size, [P | Acc]).

%% The largest cut at or below Size not inside a UTF-8 sequence.
boundary(Text, Size) when Size > 0 ->
    case binary:at(Text, Size) band 16#C0 of
        16#80 -> boundary(Text, Size - 1);
        _ -> Size
    end;
boundary(Text, 0) ->
    <<Char/utf8, _/binary>> = Text,
    byte_size(<<Char/utf8>>).

%%====================================================================
%% Encoding and reading
%%====================================================================

%% @doc An operation as JSON text; `error' for a message that is not JSON.
-spec encode(op()) -> {ok, binary()} | error.
encode(Op) ->
    try {ok, iolist_to_binary(jiffy:encode(Op))}
    catch _:_ -> error
    end.

%% @doc An operation as CBOR (`toroco_ros_cbor').
-spec cbor(op()) -> binary().
cbor(Op) ->
    toroco_ros_cbor:encode(Op).

%% @doc A text received: `{ok, {Op, Id, Fields}}' (`Id' `null' when it
%% has none), or why it is not an operation.
-spec decode(binary()) -> {ok, {binary(), term(), map()}} | {error, not_json | not_an_op}.
decode(Text) ->
    try jiffy:decode(Text, [return_maps]) of
        #{<<"op">> := Op} = M when is_binary(Op) -> {ok, {Op, maps:get(<<"id">>, M, null), M}};
        _ -> {error, not_an_op}
    catch _:_ -> {error, not_json}
    end.

%% @doc What a server's operation says to the client: a message on a
%% topic, a topic it refused (an error status about the client's advertise
%% or subscribe of it), another status, or nothing of the client's.
-spec read(binary()) -> {publish, binary(), term()} | {refused, binary(), map()}
                            | {status, map()} | other.
read(Text) ->
    case decode(Text) of
        {ok, {<<"publish">>, _, #{<<"topic">> := Topic, <<"msg">> := Msg}}} ->
            {publish, Topic, Msg};
        {ok, {<<"status">>, Id, St = #{<<"level">> := <<"error">>}}} ->
            case Id of
                <<"advertise:", Topic/binary>> -> {refused, Topic, St};
                <<"subscribe:", Topic/binary>> -> {refused, Topic, St};
                _ -> {status, St}
            end;
        {ok, {<<"status">>, _, St}} -> {status, St};
        _ -> other
    end.

%% @doc The token an `auth' operation carries (`mac', or `token').
-spec auth_token(map()) -> binary() | none.
auth_token(#{<<"token">> := T}) when is_binary(T) -> T;
auth_token(#{<<"mac">> := T}) when is_binary(T) -> T;
auth_token(_) -> none.

%% @doc A status level's rank (`set_level' and the statuses sent): the
%% least severe a client hears is the level it set.
-spec level(binary() | info | warning | error) -> {ok, 1..4} | error.
level(L) when L =:= <<"info">>; L =:= info -> {ok, 1};
level(L) when L =:= <<"warning">>; L =:= warning -> {ok, 2};
level(L) when L =:= <<"error">>; L =:= error -> {ok, 3};
level(<<"none">>) -> {ok, 4};
level(_) -> error.

%% @doc A `fragment' operation's fields: `{ok, Num, Total, Data}', or
%% `error' when they are not a piece of a message.
-spec fragment(map()) -> {ok, non_neg_integer(), pos_integer(), binary()} | error.
fragment(#{<<"data">> := Data, <<"num">> := Num, <<"total">> := Total})
  when is_binary(Data), is_integer(Num), is_integer(Total), Total > 0, Num >= 0, Num < Total ->
    {ok, Num, Total, Data};
fragment(_) ->
    error.
