#include "daemon/live_view/websocket_transport.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <map>
#include <set>
#include <system_error>
#include <thread>
#include <vector>

#include <malloc.h>
#include <sys/socket.h>

#define ASIO_STANDALONE
#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

#include "base/descriptor_budget.hpp"
#include "daemon/live_view/admission.hpp"

namespace stereod::live_view {

namespace {

// Client messages are small JSON requests; anything larger is refused by websocketpp
// (close 1009) instead of being buffered.
constexpr std::size_t kMaxClientMessage = 64 * 1024;
// With every connection slot taken, whether one has ended is looked at this often.
constexpr std::chrono::milliseconds kFullRetry{100};
// Out of descriptors: the first wait before accepting again, doubled up to the last.
constexpr std::chrono::milliseconds kBackoffFirst{100};
constexpr std::chrono::milliseconds kBackoffLast{1600};

// A connection's share of the count of open sockets: taken when its socket is accepted,
// given back when websocketpp destroys the connection (after its socket is closed, and
// whichever way it ended: a session, an HTTP request, a failed or timed-out handshake).
struct ConnectionSlot {
    std::shared_ptr<std::atomic<std::size_t>> open;
    ~ConnectionSlot()
    {
        if (open)
            open->fetch_sub(1, std::memory_order_relaxed);
    }
};

struct Config : websocketpp::config::asio {
    typedef ConnectionSlot connection_base;
};

using Server = websocketpp::server<Config>;
using Handle = websocketpp::connection_hdl;
using Acceptor = std::shared_ptr<asio::ip::tcp::acceptor>;

HttpResponse refusal(int status, const std::string& why)
{
    return HttpResponse{status, "text/plain; charset=utf-8", "live view: " + why + "\n"};
}

} // namespace

struct WebSocketTransport::Impl {
    WebSocketTransport& owner;
    Handlers handlers;
    std::string subprotocol;
    TransportLimits limits;
    Server server;
    std::thread thread;
    uint16_t port = 0;
    ConnectionId next_id = 1;
    std::map<ConnectionId, Handle> by_id;
    std::map<Handle, ConnectionId, std::owner_less<Handle>> by_handle;
    // Handshakes accepted and not open yet: they count against max_clients too.
    std::set<Handle, std::owner_less<Handle>> admitted;

    // The accept loop (I/O thread): our own instead of websocketpp's start_accept(), which
    // accepts without limit and retries at once after EMFILE.
    std::shared_ptr<std::atomic<std::size_t>> open_connections =
        std::make_shared<std::atomic<std::size_t>>(0);
    Acceptor acceptor; // websocketpp's, handed to us before it binds
    std::unique_ptr<asio::steady_timer> accept_timer;
    std::chrono::milliseconds backoff{0};
    bool stopping = false;
    SpareDescriptor spare;

    Impl(WebSocketTransport& transport, Handlers h) : owner(transport), handlers(std::move(h)) {}

    Server::connection_ptr connection(ConnectionId id) const
    {
        const auto it = by_id.find(id);
        if (it == by_id.end())
            return nullptr;
        websocketpp::lib::error_code ec;
        auto con = const_cast<Server&>(server).get_con_from_hdl(it->second, ec);
        return ec ? nullptr : con;
    }

    // The request's admission, or the refusal to send (status 0: admitted).
    HttpResponse admission(const Server::connection_ptr& con, bool& token_in_url) const
    {
        const std::string& resource = con->get_resource();
        if (resource.empty() || resource.front() != '/')
            return refusal(400, "a request's target must be an absolute path");
        const RequestView request{resource, con->get_request_header("Origin"),
                                  con->get_request_header("Host"),
                                  con->get_request_header("Cookie")};
        const Admission verdict = admit(request, limits.token, limits.allowed_origins, port);
        token_in_url = verdict == Admission::Allowed && tokenInUrl(request, limits.token);
        if (verdict == Admission::Allowed)
            return HttpResponse{0, {}, {}};
        return refusal(verdict == Admission::ForeignOrigin ? 403 : 401, admissionText(verdict));
    }

    void refuse(const Server::connection_ptr& con, const HttpResponse& response)
    {
        owner.refused_.fetch_add(1, std::memory_order_relaxed);
        con->set_status(static_cast<websocketpp::http::status_code::value>(response.status));
        con->append_header("Content-Type", response.content_type);
        con->set_body(response.body);
    }

    void acceptLater(std::chrono::milliseconds delay)
    {
        accept_timer->expires_after(delay);
        accept_timer->async_wait([this](const std::error_code& ec) {
            if (!ec)
                acceptNext();
        });
    }

    void acceptNext()
    {
        if (stopping)
            return;
        if (open_connections->load(std::memory_order_relaxed) >= limits.max_connections) {
            acceptLater(kFullRetry); // the backlog holds the rest meanwhile
            return;
        }
        Server::connection_ptr con = server.get_connection();
        if (!con) {
            acceptLater(kBackoffFirst);
            return;
        }
        websocketpp::lib::error_code ec;
        server.async_accept(
            con, [this, con](const websocketpp::lib::error_code& error) { onAccepted(con, error); },
            ec);
        if (ec)
            con->terminate(ec); // not listening any more: stopping
    }

    void onAccepted(const Server::connection_ptr& con, const websocketpp::lib::error_code& ec)
    {
        if (ec) {
            con->terminate(ec);
            if (stopping || ec == websocketpp::error::operation_canceled)
                return;
            if (outOfDescriptors(ec.value()) && acceptor) {
                // The connection waiting is told and closed on the spare descriptor, so the
                // listening socket stops being readable; then the loop waits.
                static const std::string busy =
                    "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain\r\n"
                    "Connection: close\r\n\r\nlive view: the service is out of file "
                    "descriptors; try again later\n";
                if (spare.refuseWaitingConnection(acceptor->native_handle(), [](int fd) {
                        [[maybe_unused]] const ssize_t n =
                            ::send(fd, busy.data(), busy.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
                    }))
                    owner.refused_.fetch_add(1, std::memory_order_relaxed);
            }
            backoff = std::clamp(backoff * 2, kBackoffFirst, kBackoffLast);
            acceptLater(backoff);
            return;
        }
        backoff = std::chrono::milliseconds(0);
        open_connections->fetch_add(1, std::memory_order_relaxed);
        con->open = open_connections;
        con->start();
        acceptNext();
    }
};

WebSocketTransport::WebSocketTransport(Handlers handlers)
    : impl_(std::make_unique<Impl>(*this, std::move(handlers)))
{
}

WebSocketTransport::~WebSocketTransport()
{
    stop();
}

std::string WebSocketTransport::start(const std::string& host, uint16_t port,
                                      const std::string& subprotocol, TransportLimits limits)
{
    Impl& d = *impl_;
    d.subprotocol = subprotocol;
    d.limits = std::move(limits);
    Server& s = d.server;
    s.clear_access_channels(websocketpp::log::alevel::all);
    s.clear_error_channels(websocketpp::log::elevel::all);
    websocketpp::lib::error_code ec;
    s.init_asio(ec);
    if (ec)
        return ec.message();
    d.accept_timer = std::make_unique<asio::steady_timer>(s.get_io_service());
    s.set_reuse_addr(true);
    s.set_max_message_size(kMaxClientMessage);
    s.set_max_http_body_size(kMaxClientMessage);
    s.set_tcp_pre_bind_handler([&d](Acceptor acceptor) {
        d.acceptor = std::move(acceptor);
        return websocketpp::lib::error_code();
    });

    s.set_validate_handler([&d](Handle hdl) {
        websocketpp::lib::error_code error;
        auto con = d.server.get_con_from_hdl(hdl, error);
        if (error)
            return false;
        bool token_in_url = false;
        const HttpResponse refused = d.admission(con, token_in_url);
        if (refused.status != 0) {
            d.refuse(con, refused);
            return false;
        }
        const auto& offered = con->get_requested_subprotocols();
        if (std::find(offered.begin(), offered.end(), d.subprotocol) == offered.end()) {
            con->set_status(websocketpp::http::status_code::bad_request);
            con->set_body("this server speaks the WebSocket subprotocol " + d.subprotocol + "\n");
            return false;
        }
        if (d.by_id.size() + d.admitted.size() >= d.limits.max_clients) {
            d.refuse(con, refusal(503, std::to_string(d.by_id.size() + d.admitted.size()) +
                                           " clients are connected, the most it takes "
                                           "(live_view.max_clients)"));
            return false;
        }
        con->select_subprotocol(d.subprotocol, error);
        if (error)
            return false;
        d.admitted.insert(hdl);
        return true;
    });
    s.set_open_handler([&d](Handle hdl) {
        d.admitted.erase(hdl);
        const ConnectionId id = d.next_id++;
        d.by_id[id] = hdl;
        d.by_handle[hdl] = id;
        if (d.handlers.opened)
            d.handlers.opened(id);
    });
    const auto gone = [&d](Handle hdl) {
        d.admitted.erase(hdl);
        const auto it = d.by_handle.find(hdl);
        if (it == d.by_handle.end())
            return;
        const ConnectionId id = it->second;
        d.by_handle.erase(it);
        d.by_id.erase(id);
        if (d.handlers.closed)
            d.handlers.closed(id);
        // The last client gone: what the clients' queues held goes back to the system
        // rather than stay in the allocator's free lists.
        if (d.by_id.empty())
            ::malloc_trim(0);
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
        bool token_in_url = false;
        HttpResponse response = d.admission(con, token_in_url);
        if (response.status != 0) {
            d.refuse(con, response);
            return;
        }
        if (con->get_request().get_method() != "GET" || !d.handlers.http) {
            response = refusal(405, "only GET is served here");
        } else {
            response = d.handlers.http(con->get_resource());
            // A page opened with the token keeps it in a cookie for its own requests.
            if (token_in_url)
                con->append_header("Set-Cookie", tokenCookie(d.limits.token, d.port));
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
    asio::error_code local_error;
    const auto local = s.get_local_endpoint(local_error);
    d.port = local_error ? port : local.port();
    d.acceptNext();
    d.thread = std::thread([&d] { d.server.run(); });
    return {};
}

void WebSocketTransport::stop()
{
    Impl& d = *impl_;
    if (!d.thread.joinable())
        return;
    d.server.get_io_service().post([&d] {
        d.stopping = true;
        d.accept_timer->cancel();
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

bool WebSocketTransport::sendReply(ConnectionId id, const std::string& text,
                                   std::size_t max_backlog_bytes)
{
    if (buffered(id) > max_backlog_bytes) {
        closed_for_replies_.fetch_add(1, std::memory_order_relaxed);
        close(id, "too slow: not reading its replies");
        return false;
    }
    return sendText(id, text);
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
