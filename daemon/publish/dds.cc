#include "publish/dds.h"

#include <utility>

namespace hg::publish::dds {

Error::Error(const std::string& what, dds_return_t code)
    : std::runtime_error(what + ": " + dds_strretcode(code) + " (" + std::to_string(code) + ")"),
      code_(code) {}

dds_return_t Check(dds_return_t rc, const char* what) {
  if (rc < 0) throw Error(what, rc);
  return rc;
}

dds_duration_t ToDuration(std::chrono::nanoseconds d) {
  return d.count() < 0 ? 0 : static_cast<dds_duration_t>(d.count());
}

Qos::Qos() : qos_(dds_create_qos()) {
  if (qos_ == nullptr) throw Error("dds_create_qos", DDS_RETCODE_OUT_OF_RESOURCES);
}

Qos::~Qos() {
  if (qos_ != nullptr) dds_delete_qos(qos_);
}

Qos::Qos(Qos&& other) noexcept : qos_(std::exchange(other.qos_, nullptr)) {}

Qos& Qos::operator=(Qos&& other) noexcept {
  if (this != &other) {
    if (qos_ != nullptr) dds_delete_qos(qos_);
    qos_ = std::exchange(other.qos_, nullptr);
  }
  return *this;
}

Entity::Entity(dds_entity_t handle, const char* what) : handle_(Check(handle, what)) {}

Entity::~Entity() { Reset(); }

Entity::Entity(Entity&& other) noexcept : handle_(std::exchange(other.handle_, 0)) {}

Entity& Entity::operator=(Entity&& other) noexcept {
  if (this != &other) {
    Reset();
    handle_ = std::exchange(other.handle_, 0);
  }
  return *this;
}

void Entity::Reset() {
  // The return code is ignored on purpose: a child whose participant was
  // deleted first is already gone (DDS_RETCODE_BAD_PARAMETER).
  if (handle_ > 0) dds_delete(handle_);
  handle_ = 0;
}

Participant::Participant(dds_domainid_t domain, const dds_qos_t* qos)
    : Entity(dds_create_participant(domain, qos, nullptr), "dds_create_participant") {}

Topic::Topic(const Participant& participant, const dds_topic_descriptor_t* type,
             const std::string& name, const dds_qos_t* qos)
    : Entity(dds_create_topic(participant.handle(), type, name.c_str(), qos, nullptr),
             ("dds_create_topic \"" + name + "\"").c_str()) {}

Writer::Writer(const Participant& participant, const Topic& topic, const dds_qos_t* qos)
    : Entity(dds_create_writer(participant.handle(), topic.handle(), qos, nullptr),
             "dds_create_writer") {}

dds_return_t Writer::Write(const void* sample) const { return dds_write(handle(), sample); }

Reader::Reader(const Participant& participant, const Topic& topic, const dds_qos_t* qos,
               const dds_listener_t* listener)
    : Entity(dds_create_reader(participant.handle(), topic.handle(), qos, listener),
             "dds_create_reader") {}

WaitSet::WaitSet(const Participant& participant)
    : Entity(dds_create_waitset(participant.handle()), "dds_create_waitset") {}

void WaitSet::Attach(const Entity& entity, dds_attach_t token) {
  Check(dds_waitset_attach(handle(), entity.handle(), token), "dds_waitset_attach");
}

int WaitSet::Wait(dds_attach_t* tokens, std::size_t capacity, std::chrono::nanoseconds timeout) {
  return Check(dds_waitset_wait(handle(), tokens, capacity, ToDuration(timeout)),
               "dds_waitset_wait");
}

}  // namespace hg::publish::dds
