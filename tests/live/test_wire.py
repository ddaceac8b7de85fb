"""The protocol's messages: golden bytes out, every malformed client frame refused."""

from __future__ import annotations

import json
import struct

import pytest

from ocu.live import wire


def test_message_data_is_opcode_subscription_time_payload_little_endian() -> None:
    frame = wire.message_data(0x01020304, 0x1122334455667788, b"\xaa\xbb")
    assert frame == (
        b"\x01" + b"\x04\x03\x02\x01" + b"\x88\x77\x66\x55\x44\x33\x22\x11" + b"\xaa\xbb"
    )


def test_fetch_asset_answers_are_opcode_id_status_error_data() -> None:
    assert wire.fetch_asset_response(7, b"STL") == (
        b"\x04" + b"\x07\x00\x00\x00" + b"\x00" + b"\x00\x00\x00\x00" + b"STL"
    )
    assert wire.fetch_asset_response(1, None, "no") == (
        b"\x04" + b"\x01\x00\x00\x00" + b"\x01" + b"\x02\x00\x00\x00" + b"no"
    )
    assert wire.parse_client_message('{"op":"fetchAsset","uri":"package://a/b","requestId":3}') == (
        wire.FetchAsset("package://a/b", 3)
    )


def test_client_publish_messages_are_read() -> None:
    advertise = (
        '{"op":"advertise","channels":[{"id":2,"topic":"/cmd_vel","encoding":"json",'
        '"schemaName":"geometry_msgs/msg/Twist"}]}'
    )
    assert wire.parse_client_message(advertise) == wire.ClientAdvertise(
        (wire.ClientChannel(2, "/cmd_vel", "json", "geometry_msgs/msg/Twist"),)
    )
    assert wire.parse_client_message('{"op":"unadvertise","channelIds":[2]}') == (
        wire.ClientUnadvertise((2,))
    )
    assert wire.parse_client_message(b"\x01\x02\x00\x00\x00{}") == wire.ClientPublish(2, b"{}")


def test_advertise_names_the_ros2_encodings() -> None:
    text = wire.advertise([wire.ChannelInfo(3, "/joint_states", "sensor_msgs/msg/JointState", "x")])
    assert json.loads(text) == {
        "op": "advertise",
        "channels": [
            {
                "id": 3,
                "topic": "/joint_states",
                "encoding": "cdr",
                "schemaName": "sensor_msgs/msg/JointState",
                "schema": "x",
                "schemaEncoding": "ros2msg",
            }
        ],
    }


def test_subscribe_and_unsubscribe_are_read() -> None:
    message = wire.parse_client_message(
        '{"op":"subscribe","subscriptions":[{"id":0,"channelId":5},{"id":1,"channelId":6}]}'
    )
    assert message == wire.Subscribe(((0, 5), (1, 6)))
    assert wire.parse_client_message('{"op":"unsubscribe","subscriptionIds":[1]}') == (
        wire.Unsubscribe((1,))
    )


@pytest.mark.parametrize(
    ("frame", "reason"),
    [
        (b"\x01\x02", "binary frame: not a message"),
        (b"\x03\x00\x00\x00\x00", "binary frame: not a message"),
        (b"\x02\x00\x00\x00\x00", "service call: shorter than its header"),
        (b"\x02" + struct.pack("<III", 1, 2, 9) + b"json", "service call: a bad encoding length"),
        (b"\x02" + struct.pack("<III", 1, 2, 2) + b"\xff\xfe", "the encoding is not ASCII"),
        ('{"op":"advertise","channels":[{"id":1,"topic":5}]}', "topic, encoding and schemaName"),
        ('{"op":"advertise","channels":[3]}', "each channel must be an object"),
        ('{"op":"unadvertise","channelIds":[-1]}', "channel id"),
        ("not json", "not JSON"),
        ("[1, 2]", "not a JSON object"),
        ("[" * 100000, "not JSON"),
        ('{"op":"publish"}', "operation 'publish' is not supported"),
        ('{"op":"subscribe"}', "'subscriptions' must be a list"),
        ('{"op":"subscribe","subscriptions":[7]}', "each subscription must be an object"),
        ('{"op":"subscribe","subscriptions":[{"id":-1,"channelId":1}]}', "subscription id"),
        ('{"op":"subscribe","subscriptions":[{"id":true,"channelId":1}]}', "subscription id"),
        ('{"op":"subscribe","subscriptions":[{"id":1,"channelId":4294967296}]}', "channel id"),
        ('{"op":"unsubscribe","subscriptionIds":["1"]}', "subscription id"),
        ('{"op":"fetchAsset","uri":7,"requestId":1}', "'uri' must be a string"),
        ('{"op":"fetchAsset","uri":"' + "x" * 5000 + '","requestId":1}', "'uri' must be"),
        ('{"op":"fetchAsset","uri":"a","requestId":-2}', "request id"),
        ('{"op":"unsubscribe","subscriptionIds":' + json.dumps(list(range(5000))) + "}", "more"),
    ],
)
def test_malformed_client_frames_are_refused_with_the_reason(
    frame: str | bytes, reason: str
) -> None:
    with pytest.raises(wire.ClientMessageError, match=reason):
        wire.parse_client_message(frame)


def test_service_calls_and_their_answers_are_the_protocols_bytes() -> None:
    frame = b"\x02" + struct.pack("<III", 7, 9, 4) + b"json" + b'{"name":"ready"}'
    assert wire.parse_client_message(frame) == wire.ServiceCallRequest(
        7, 9, "json", b'{"name":"ready"}'
    )
    answer = wire.service_call_response(7, 9, "cdr", b"\x00\x01\x00\x00\x01")
    assert answer == b"\x03" + struct.pack("<III", 7, 9, 3) + b"cdr" + b"\x00\x01\x00\x00\x01"
    failure = json.loads(wire.service_call_failure(7, 9, "no service 7"))
    assert failure == {
        "op": "serviceCallFailure",
        "serviceId": 7,
        "callId": 9,
        "message": "no service 7",
    }
