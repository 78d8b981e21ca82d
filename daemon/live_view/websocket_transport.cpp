#include "daemon/live_view/websocket_transport.hpp"

#include <algorithm>
#include <map>
#include <thread>
#include <vector>

#define ASIO_STANDALONE
#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

namespace stereod::live_view {

namespace {

using Server = websocketpp::server<websocketpp::config::asio>;
using Handle = websocketpp::connection_hdl;

// Client messages are small JSON requests; anything larger is refused by websocketpp
// (close 1009) instead of being buffered.
constexpr std::size_t kMaxClientMessage = 64 * 1024;

} // namespace

struct WebSocketTransport::Impl {
    Handlers handlers;
    std::string subprotocol;
    Server server;
    std::thread thread;
    uint16_t port = 0;
    ConnectionId next_id = 1;
    std::map<ConnectionId, Handle> by_id;
    std::map<Handle, ConnectionId, std::owner_less<Handle>> by_handle;

    Server::connection_ptr connection(ConnectionId id) const
    {
        const auto it = by_id.find(id);
        if (it == by_id.end())
            return nullptr;
        websocketpp::lib::error_code ec;
        auto con = const_cast<Server&>(server).get_con_from_hdl(it->second, ec);
        return ec ? nullptr : con;
    }
};

WebSocketTransport::WebSocketTransport(Handlers handlers) : impl_(std::make_unique<Impl>())
{
    impl_->handlers = std::move(handlers);
}

WebSocketTransport::~WebSocketTransport()
{
    stop();
}

std::string WebSocketTransport::start(const std::string& host, uint16_t port,
                                      const std::string& subprotocol)
{
    Impl& d = *impl_;
    d.subprotocol = subprotocol;
    Server& s = d.server;
    s.clear_access_channels(websocketpp::log::alevel::all);
    s.clear_error_channels(websocketpp::log::elevel::all);
    websocketpp::lib::error_code ec;
    s.init_asio(ec);
    if (ec)
        return ec.message();
    s.set_reuse_addr(true);
    s.set_max_message_size(kMaxClientMessage);
    s.set_max_http_body_size(kMaxClientMessage);

    s.set_validate_handler([&d](Handle hdl) {
        websocketpp::lib::error_code error;
        auto con = d.server.get_con_from_hdl(hdl, error);
        if (error)
            return false;
        const auto& offered = con->get_requested_subprotocols();
        if (std::find(offered.begin(), offered.end(), d.subprotocol) == offered.end()) {
            con->set_status(websocketpp::http::status_code::bad_request);
            con->set_body("this server speaks the WebSocket subprotocol " + d.subprotocol + "\n");
            return false;
        }
        con->select_subprotocol(d.subprotocol, error);
        return !error;
    });
    s.set_open_handler([&d](Handle hdl) {
        const ConnectionId id = d.next_id++;
        d.by_id[id] = hdl;
        d.by_handle[hdl] = id;
        if (d.handlers.opened)
            d.handlers.opened(id);
    });
    const auto gone = [&d](Handle hdl) {
        const auto it = d.by_handle.find(hdl);
        if (it == d.by_handle.end())
            return;
        const ConnectionId id = it->second;
        d.by_handle.erase(it);
        d.by_id.erase(id);
        if (d.handlers.closed)
            d.handlers.closed(id);
    };
    s.set_close_handler(gone);
    s.set_fail_handler(gone);
    s.set_message_handler([&d](Handle hdl, Server::message_ptr message) {
        const auto it = d.by_handle.find(hdl);
        if (it == d.by_handle.end() || !d.handlers.text)
            return;
        if (message->get_opcode() != websocketpp::frame::opcode::text) {
            websocketpp::lib::error_code error;
            d.server.close(hdl, websocketpp::close::status::unsupported_data,
                           "binary client messages are not offered", error);
            return;
        }
        d.handlers.text(it->second, message->get_payload());
    });
    s.set_http_handler([&d](Handle hdl) {
        websocketpp::lib::error_code error;
        auto con = d.server.get_con_from_hdl(hdl, error);
        if (error)
            return;
        HttpResponse response;
        if (con->get_request().get_method() != "GET" || !d.handlers.http) {
            response.status = 405;
            response.body = "only GET is served here\n";
        } else {
            response = d.handlers.http(con->get_resource());
        }
        con->set_status(static_cast<websocketpp::http::status_code::value>(response.status));
        con->append_header("Content-Type", response.content_type);
        con->append_header("Cache-Control", "no-store");
        con->set_body(response.body);
    });

    const auto address = asio::ip::make_address(host, ec);
    if (ec)
        return "\"" + host + "\" is not an IP address";
    s.listen(asio::ip::tcp::endpoint(address, port), ec);
    if (ec)
        return ec.message();
    s.start_accept(ec);
    if (ec)
        return ec.message();
    asio::error_code local_error;
    const auto local = s.get_local_endpoint(local_error);
    d.port = local_error ? port : local.port();
    d.thread = std::thread([&d] { d.server.run(); });
    return {};
}

void WebSocketTransport::stop()
{
    Impl& d = *impl_;
    if (!d.thread.joinable())
        return;
    d.server.get_io_service().post([&d] {
        websocketpp::lib::error_code ec;
        d.server.stop_listening(ec);
        for (const auto& [id, hdl] : d.by_id)
            d.server.close(hdl, websocketpp::close::status::going_away, "stereod stops", ec);
    });
    // Closing handshakes get a moment; then the loop is stopped whatever is pending.
    for (int i = 0; i < 50; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
        if (d.server.get_io_service().stopped())
            break;
    }
    d.server.stop();
    d.thread.join();
}

uint16_t WebSocketTransport::port() const noexcept
{
    return impl_->port;
}

void WebSocketTransport::post(std::function<void()> task)
{
    impl_->server.get_io_service().post(std::move(task));
}

bool WebSocketTransport::sendText(ConnectionId id, const std::string& text)
{
    auto con = impl_->connection(id);
    return con && !con->send(text, websocketpp::frame::opcode::text);
}

bool WebSocketTransport::sendBinary(ConnectionId id, const std::string& bytes)
{
    auto con = impl_->connection(id);
    return con && !con->send(bytes, websocketpp::frame::opcode::binary);
}

std::size_t WebSocketTransport::buffered(ConnectionId id) const
{
    auto con = impl_->connection(id);
    return con ? con->get_buffered_amount() : 0;
}

void WebSocketTransport::close(ConnectionId id, const std::string& reason)
{
    auto con = impl_->connection(id);
    if (!con)
        return;
    websocketpp::lib::error_code ec;
    con->close(websocketpp::close::status::policy_violation, reason, ec);
    // The close frame waits behind what the client has not read, maybe for ever: the
    // socket is shut down too, which ends the connection (and calls the closed handler)
    // whether or not the client ever reads again.
    asio::error_code shutdown_ec;
    con->get_raw_socket().shutdown(asio::ip::tcp::socket::shutdown_both, shutdown_ec);
}

} // namespace stereod::live_view
