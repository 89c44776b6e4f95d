"""A node's parameters through the services ``ros2 param`` uses (``rcl_interfaces``): list, get,
describe and set, from a test's ``CliNode``."""
from __future__ import annotations

from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters, SetParameters


def listed(cli, node: str) -> set[str]:
    from qg_common.ros_client import RESEND_AFTER, call_service
    reply = call_service(cli, ListParameters, f"{node}/list_parameters",
                         ListParameters.Request(), timeout=30.0, resend_after=RESEND_AFTER)
    return set(reply.result.names)


def get(cli, node: str, *names: str) -> list:
    from qg_common.ros_client import RESEND_AFTER, call_service
    from rclpy.parameter import parameter_value_to_python
    values = call_service(cli, GetParameters, f"{node}/get_parameters",
                          GetParameters.Request(names=list(names)),
                          resend_after=RESEND_AFTER).values
    return [parameter_value_to_python(v) for v in values]


def describe(cli, node: str, name: str):
    from qg_common.ros_client import RESEND_AFTER, call_service
    return call_service(cli, DescribeParameters, f"{node}/describe_parameters",
                        DescribeParameters.Request(names=[name]),
                        resend_after=RESEND_AFTER).descriptors[0]


def set_double(cli, node: str, name: str, value: float):
    return set_value(cli, node, name, ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                                     double_value=value))


def set_value(cli, node: str, name: str, value: ParameterValue):
    from qg_common.ros_client import RESEND_AFTER, call_service
    request = SetParameters.Request(parameters=[Parameter(name=name, value=value)])
    return call_service(cli, SetParameters, f"{node}/set_parameters", request,
                        resend_after=RESEND_AFTER).results[0]


def integer(value: int) -> ParameterValue:
    return ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)


def string(value: str) -> ParameterValue:
    return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
