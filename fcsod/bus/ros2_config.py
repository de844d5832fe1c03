"""``[ros2]`` settings and the names rmw_zenoh gives: light to import (the daemon's config and the PKI use them)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

#: Admin space of rmw_zenoh's liveliness tokens.
LIVELINESS_ADMIN_SPACE = "@ros2_lv"


#: A ROS 2 name token (node names, namespace parts).
NAME_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"


class Ros2Config(BaseModel):
    """``[ros2]``: the daemon as a ROS 2 node on zenoh, in rmw_zenoh's wire format."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    enabled: bool = Field(False, description="Also publish the ROS 2 topics on the daemon's zenoh session")
    domain_id: int = Field(0, ge=0, le=232, description="ROS_DOMAIN_ID of the cell")
    namespace: str = Field(
        "/", pattern=rf"^/({NAME_TOKEN}(/{NAME_TOKEN})*)?$", description="ROS 2 namespace of the node, e.g. /cell1"
    )
    node_name: str = Field("fcsod", pattern=rf"^{NAME_TOKEN}$", description="ROS 2 node name")
    history_depth: int = Field(
        10, ge=1, description="Keep-last depth: samples per topic a late transient-local subscriber receives"
    )
