// statectl runtime: everything a generated device includes.
#ifndef STATECTL_RUNTIME_HPP
#define STATECTL_RUNTIME_HPP

#include "statectl/contract.hpp"
#include "statectl/observer.hpp"
#include "statectl/spsc_queue.hpp"
#include "statectl/trace.hpp"

#endif  // STATECTL_RUNTIME_HPP
