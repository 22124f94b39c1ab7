//! Creating the node's DDS endpoints (publishers, subscriptions, service servers, all with the
//! default QoS) from their rows of `ros::topics`, and the input streams that own them, so the
//! node's event set can hold them for as long as it serves.

use std::rc::Rc;
use std::time::Duration;

use futures::stream::{self, Stream};
use ros2_client::{
    Message, MessageInfo, Name, Node, Publisher, ReadResult, RmwRequestId, Server as ServiceServer, ServiceMapping,
    ServiceTypeName, Subscription,
};
use serde::de::DeserializeOwned;
use serde::Serialize;

use super::log::log;
use crate::ros::messages::Typed;
use crate::ros::qos::default_profile;
use crate::ros::topics::{Kind, Qos, Topic};

pub(super) fn topic_name(absolute: &str) -> Result<Name, String> {
    Name::parse(absolute).map_err(|e| format!("'{absolute}' is not a valid topic name: {e:?}"))
}

/// That `topic`'s row is what the node is about to create at `absolute` (a wrong row is a bug of
/// the node's, caught by its first start in any test).
fn fits(topic: &Topic, kind: Kind, type_name: (&str, &str), absolute: &str) -> Result<(), String> {
    let row = (topic.kind, topic.qos, (topic.ty.package, topic.ty.name));
    if row == (kind, Qos::Default, type_name) {
        Ok(())
    } else {
        Err(format!("{absolute}: created as {kind:?} of {type_name:?} with the default QoS, but its row is {topic:?}"))
    }
}

pub(super) fn publisher<M: Message + Serialize + Typed>(
    node: &mut Node,
    topic: &Topic,
    absolute: &str,
) -> Result<Publisher<M>, String> {
    let t = M::type_name();
    fits(topic, Kind::Publishes, (t.package_name(), t.type_name()), absolute)?;
    let qos = default_profile();
    let topic = node
        .create_topic(&topic_name(absolute)?, M::type_name(), &qos)
        .map_err(|e| format!("cannot create topic {absolute}: {e:?}"))?;
    node.create_publisher(&topic, Some(qos)).map_err(|e| format!("cannot publish {absolute}: {e:?}"))
}

pub(super) fn subscription<M>(node: &mut Node, topic: &Topic, absolute: &str) -> Result<Subscription<M>, String>
where
    M: Message + Typed + DeserializeOwned + 'static,
{
    let t = M::type_name();
    fits(topic, Kind::Subscribes, (t.package_name(), t.type_name()), absolute)?;
    let qos = default_profile();
    let topic = node
        .create_topic(&topic_name(absolute)?, M::type_name(), &qos)
        .map_err(|e| format!("cannot create topic {absolute}: {e:?}"))?;
    node.create_subscription(&topic, Some(qos)).map_err(|e| format!("cannot subscribe {absolute}: {e:?}"))
}

/// A service server, shared (`Rc`) between the stream of its requests and whoever answers them.
pub(super) fn service<Req, Resp>(
    node: &mut Node,
    topic: &Topic,
    absolute: &str,
    service: ServiceTypeName,
) -> Result<Rc<ServiceServer<Req, Resp>>, String>
where
    Req: Message + Clone + DeserializeOwned + 'static,
    Resp: Message + Serialize + 'static,
{
    fits(topic, Kind::Service, (service.package_name(), service.type_name()), absolute)?;
    let qos = default_profile();
    node.create_server(
        ServiceMapping::Enhanced, // what rmw_fastrtps_cpp (Jazzy's default) speaks
        &topic_name(absolute)?,
        &service,
        qos.clone(),
        qos,
    )
    .map(Rc::new)
    .map_err(|e| format!("cannot serve {absolute}: {e:?}"))
}

/// The requests to `server`, from a stream that holds it (with whoever answers them).
pub(super) fn requests<Req, Resp>(
    server: &Rc<ServiceServer<Req, Resp>>,
) -> impl Stream<Item = ReadResult<(RmwRequestId, Req)>> + 'static
where
    Req: Message + Clone + DeserializeOwned + 'static,
    Resp: Message + Serialize + 'static,
{
    stream::unfold(Rc::clone(server), |server| async move {
        let received = server.async_receive_request().await;
        Some((received, server))
    })
}

/// How long a reply waits for its client's reply reader to be matched (see [`respond`]).
pub(super) const REPLY_READER_WAIT: Duration = Duration::from_secs(2);

/// Sends `response` to the request `id` of `service`, once `server` has matched a reader of the
/// participant that sent the request, i.e. the client's reply reader: right after discovery the
/// node can match a client's request writer before its reply reader, and a reply sent then is
/// lost for good (the reply writer is volatile; a Cyclone DDS client saw the reset happen and no
/// reply come, 1 run in 10 beside two CPU hogs). Waits at most [`REPLY_READER_WAIT`], then sends
/// anyway and says so; a reply that cannot be sent is logged too. The node's other inputs wait
/// meanwhile; a reply reader that exists is matched within milliseconds, and one that is already
/// matched costs nothing.
pub(super) async fn respond<Req, Resp>(
    server: &ServiceServer<Req, Resp>,
    service: &str,
    id: RmwRequestId,
    response: Resp,
) where
    Req: Message + 'static,
    Resp: Message + Serialize + 'static,
{
    if within(REPLY_READER_WAIT, server.async_wait_for_requester(id)).await.is_none() {
        log(
            "WARN",
            format!(
                "{service}: the requester's reply reader was not matched within {} s; replying anyway, \
                 the reply may not arrive",
                REPLY_READER_WAIT.as_secs_f64()
            ),
        );
    }
    if let Err(error) = server.async_send_response(id, response).await {
        log("WARN", format!("{service}: cannot send the response: {error:?}"));
    }
}

/// `future`'s output, or `None` if it takes longer than `limit`.
pub(super) async fn within<T>(limit: Duration, future: impl std::future::Future<Output = T>) -> Option<T> {
    let late = async {
        smol::Timer::after(limit).await;
        None
    };
    smol::future::or(async { Some(future.await) }, late).await
}

/// The messages of a subscription, from a stream that owns it: the subscription leaves the graph
/// when the stream is dropped.
pub(super) fn messages<M>(subscription: Subscription<M>) -> impl Stream<Item = ReadResult<(M, MessageInfo)>> + 'static
where
    M: DeserializeOwned + 'static,
{
    stream::unfold(subscription, |subscription| async move {
        let received = subscription.async_take().await;
        Some((received, subscription))
    })
}
