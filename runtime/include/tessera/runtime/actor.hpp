// Actor: the unit of computation. An actor declares in configure() what it subscribes to, what
// it publishes and which timers it needs; the runtime wires topics to its mailboxes and calls its
// handlers one at a time (never concurrently for one actor, so actors need no locks). Many
// actors run at once on the executor; inside a handler, use TBB algorithms for data-parallel work.
//
// Topic names given here are the actor's local names; a profile may remap them to global ones.
// Lifecycle: configure() -> start() -> handlers/timers -> stop(). stop() is called after every
// actor upstream of this one has stopped and its output has been delivered, so an actor may
// still publish in stop() (a final map) and a writer may write files in its stop().
#pragma once

#include <tessera/messages/message.hpp>
#include <tessera/runtime/clock.hpp>
#include <tessera/runtime/mailbox.hpp>

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <variant>

namespace tessera {

class ActorContext;

namespace detail {
struct TopicState;  // runtime-internal
/// Storage for a new message on `topic`: heap, or shared memory when the topic is exported.
std::shared_ptr<LoanStorage> loanStorage(TopicState* topic, std::size_t size_hint_bytes,
                                         std::size_t blob_bytes = 0);
using RawHandler = std::function<void(const std::shared_ptr<const MessageStorage>&)>;
}  // namespace detail

/// Key figures an actor reports for summary.json and the exit report.
using SummaryValue = std::variant<std::int64_t, double, std::string>;
using Summary = std::map<std::string, SummaryValue>;

class Actor {
 public:
  virtual ~Actor() = default;
  /// Declare subscriptions, publications and timers. Called once, before start().
  virtual void configure(ActorContext& ctx) = 0;
  virtual void start() {}
  virtual void stop() {}
  /// Figures for summary.json (e.g. scans_processed). Called after stop().
  virtual void summarize(Summary& /*out*/) const {}
};

/// Typed handle to publish on one topic. Cheap to copy; valid while the runtime lives.
template <typename T>
class Publisher {
 public:
  Publisher() = default;

  /// Starts a message; size_hint_bytes lets large arrays land in one segment.
  /// On a topic that crosses processes the message is built in a shared-memory chunk.
  Loan<T> loan(std::size_t size_hint_bytes = 0) const {
    return Loan<T>(detail::loanStorage(topic_, size_hint_bytes));
  }
  /// A loan with `blob_bytes` of uninitialised storage for one large Data field beside the
  /// message (see Loan::blob()): a payload the producer overwrites whole is written once, in
  /// place, and crosses processes without a copy. size_hint_bytes is the rest of the message.
  Loan<T> loanWithBlob(std::size_t blob_bytes, std::size_t size_hint_bytes = 0) const {
    return Loan<T>(detail::loanStorage(topic_, size_hint_bytes, blob_bytes));
  }
  /// Delivers the message to every subscriber (zero copy). May wait on reliable mailboxes.
  void publish(Loan<T>&& loan) const;
  /// Publishes an already sealed message (e.g. forwarding a received one without copying).
  void publish(const Message<T>& message) const;
  /// Next sequence number for this publisher's headers (0, 1, 2, ...).
  std::uint64_t nextSeq() const;
  const std::string& topic() const;
  bool valid() const { return topic_ != nullptr; }

 private:
  friend class ActorContext;
  friend class Runtime;
  explicit Publisher(detail::TopicState* t, std::uint32_t owner) : topic_(t), owner_(owner) {}
  detail::TopicState* topic_ = nullptr;
  std::uint32_t owner_ = 0;  // index of the publishing actor (for metrics), or external
};

/// For untyped subscriptions: the topic takes the type its publishers declare.
inline constexpr MessageType kAnyMessageType{0, "(any type)"};

/// Publishes already sealed messages whose type is fixed at advertise time but not at compile
/// time (the recording player). Subscribers read them as the advertised type.
class UntypedPublisher {
 public:
  UntypedPublisher() = default;
  void publish(std::shared_ptr<const MessageStorage> message) const;
  const std::string& topic() const;
  bool valid() const { return topic_ != nullptr; }

 private:
  friend class ActorContext;
  UntypedPublisher(detail::TopicState* t, std::uint32_t owner) : topic_(t), owner_(owner) {}
  detail::TopicState* topic_ = nullptr;
  std::uint32_t owner_ = 0;
};

namespace detail {
void publishRaw(TopicState* topic, std::uint32_t owner, std::shared_ptr<const MessageStorage> m);
std::uint64_t nextSeq(TopicState* topic);
const std::string& topicName(const TopicState* topic);
}  // namespace detail

inline void UntypedPublisher::publish(std::shared_ptr<const MessageStorage> message) const {
  detail::publishRaw(topic_, owner_, std::move(message));
}
inline const std::string& UntypedPublisher::topic() const {
  return detail::topicName(topic_);
}

template <typename T>
void Publisher<T>::publish(Loan<T>&& loan) const {
  detail::publishRaw(topic_, owner_, std::move(loan).seal());
}
template <typename T>
void Publisher<T>::publish(const Message<T>& message) const {
  detail::publishRaw(topic_, owner_, message.storage());
}
template <typename T>
std::uint64_t Publisher<T>::nextSeq() const {
  return detail::nextSeq(topic_);
}
template <typename T>
const std::string& Publisher<T>::topic() const {
  return detail::topicName(topic_);
}

/// A live look at this process's run, for viewers and monitors: cheap (a short lock per
/// actor), safe from any thread.
struct RunSnapshot {
  struct ActorFigures {
    std::string name;
    std::uint64_t messages_in = 0, messages_out = 0, drops = 0;
    std::uint64_t queue_depth = 0, max_queue_depth = 0;  ///< now, and the most so far
    double busy_s = 0;                                   ///< time in its handlers so far
  };
  double wall_s = 0;     ///< since the run started
  double sim_s = 0;      ///< runtime-clock time covered
  double progress = -1;  ///< mean progress of the finite sources in [0, 1]; -1 without any
  std::vector<ActorFigures> actors;
};

/// What an actor sees of the runtime. Given to configure(); valid for the actor's lifetime.
class ActorContext {
 public:
  virtual ~ActorContext() = default;

  template <typename T, typename Handler>
  void subscribe(std::string_view topic, MailboxPolicy policy, Handler&& handler) {
    subscribeRaw(topic, messageTypeOf<T>(), policy,
                 [h = std::forward<Handler>(handler)](
                     const std::shared_ptr<const MessageStorage>& s) { h(readMessage<T>(s)); });
  }

  template <typename T>
  Publisher<T> advertise(std::string_view topic) {
    auto [state, owner] = advertiseRaw(topic, messageTypeOf<T>());
    return Publisher<T>(state, owner);
  }

  /// Type-erased subscription for actors that carry messages without reading them (recorder,
  /// bridges). With kAnyMessageType the topic's type comes from its publishers; topicType()
  /// tells it once the runtime is configured (e.g. in start()).
  void subscribeUntyped(std::string_view topic, MessageType type, MailboxPolicy policy,
                        std::function<void(const std::shared_ptr<const MessageStorage>&)> handler) {
    subscribeRaw(topic, type, policy, std::move(handler));
  }
  /// Advertises `topic` as carrying `type` (its id must be what subscribers expect; the name
  /// must outlive the runtime, it is used in errors).
  UntypedPublisher advertiseUntyped(std::string_view topic, MessageType type) {
    auto [state, owner] = advertiseRaw(topic, type);
    return UntypedPublisher(state, owner);
  }
  /// The type a local topic of this actor carries, after configuration.
  virtual MessageType topicType(std::string_view topic) const = 0;

  /// Calls `callback` every `period` of runtime-clock time, first at now + first_delay.
  virtual void addTimer(Nanos period, std::function<void()> callback, Nanos first_delay = 0) = 0;
  /// Calls `callback` once, at runtime-clock time `when` (at once if that has passed). Players
  /// chain these to follow a dataset's own timestamps; may be called from handlers and timers.
  virtual void callAt(Nanos when, std::function<void()> callback) = 0;

  virtual const Clock& clock() const = 0;
  Nanos now() const { return clock().now(); }
  /// The actor's instance name in the profile.
  virtual const std::string& name() const = 0;
  /// Output folder of this run ("" when the run writes no files).
  virtual const std::string& outputDir() const = 0;

  /// Marks this actor as a finite input (player, simulator route). A run whose finite inputs have
  /// all finished ends by itself once everything downstream is drained.
  virtual void declareFiniteSource() = 0;
  virtual void finished() = 0;
  /// Progress of a finite source in [0, 1], shown on long runs.
  virtual void reportProgress(double fraction) = 0;
  /// Asks the whole run to stop cleanly (e.g. a fatal input error).
  virtual void requestStop(std::string_view reason) = 0;
  /// The run's figures now (RunSnapshot); from start() on, callable from any thread.
  virtual RunSnapshot snapshot() const = 0;

 protected:
  virtual void subscribeRaw(std::string_view topic, MessageType type, MailboxPolicy policy,
                            detail::RawHandler handler) = 0;
  virtual std::pair<detail::TopicState*, std::uint32_t> advertiseRaw(std::string_view topic,
                                                                     MessageType type) = 0;
};

}  // namespace tessera
