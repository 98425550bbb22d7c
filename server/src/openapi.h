// The API description served at /openapi.json; the job parameters are added to POST /v1/jobs from
// protocol::param_table() when it is served, so they cannot drift from what the parser accepts.
#pragma once

namespace hemibake::server {

inline constexpr const char* kOpenApi = R"json({
  "openapi": "3.1.0",
  "info": {"title": "hemibake", "version": "0.1.0",
           "description": "Radiosity baking service: POST a glTF scene, follow the job, fetch the baked GLB."},
  "components": {
    "securitySchemes": {"bearer": {"type": "http", "scheme": "bearer"}},
    "schemas": {
      "Error": {"type": "object", "properties": {"error": {"type": "string"}}, "required": ["error"]},
      "Progress": {"type": "object", "properties": {
        "phase": {"enum": ["shooting", "linking", "gathering", "tracing", "done", "cancelled"], "description": "shooting: aa or classical progressive refinement (also a reference job's first phase); linking and gathering: hr; tracing: a reference job's path tracing; cancelled: the bake was stopped by a DELETE, and the fraction, shots, unshot fraction and elements are where it stopped"},
        "fraction": {"type": "number", "description": "0..1 through the phase (shooting: log of the unshot fraction against the target)"},
        "links": {"type": "integer", "description": "hr only"}, "iterations": {"type": "integer", "description": "hr only"},
        "shots": {"type": "integer"}, "unshot_fraction": {"type": "number"}, "elements": {"type": "integer"},
        "elapsed_seconds": {"type": "number"}, "eta_seconds": {"type": "number", "description": "-1 when unknown"}}},
      "Job": {"type": "object", "properties": {
        "id": {"type": "string"},
        "state": {"enum": ["queued", "running", "succeeded", "failed", "cancelled"]},
        "params": {"type": "object"}, "progress": {"$ref": "#/components/schemas/Progress"},
        "scene_bytes": {"type": "integer"}, "result_bytes": {"type": "integer"}, "attempts": {"type": "integer"},
        "created": {"type": "number"}, "started": {"type": "number"}, "finished": {"type": "number"},
        "seconds": {"type": "number"}, "error": {"type": "string"}, "links": {"type": "object"}},
        "required": ["id", "state", "params"]}
    },
    "parameters": {
      "id": {"name": "id", "in": "path", "required": true, "schema": {"type": "string"}}
    },
    "responses": {
      "StoreUnavailable": {"description": "The job store is busy or cannot be reached (a shared database that is down); the error names the cause. Not an answer about the job: ask again after Retry-After",
        "headers": {"Retry-After": {"schema": {"type": "integer"}}},
        "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}}
    }
  },
  "security": [{"bearer": []}, {}],
  "paths": {
    "/v1/jobs": {
      "post": {
        "summary": "Submit a scene to bake",
        "description": "The scene as the body (model/gltf-binary or model/gltf+json, all data embedded), or multipart/form-data with a 'scene' file part and an optional 'params' JSON part. Bake parameters as query parameters (or the 'params' part's members), listed below with their defaults and limits; the command line takes the same with dashes (--max-shots). The server sets threads itself and caps max_elements and shot_cache_mb. An identical scene and parameters as a finished job are answered from the store (200, X-Hemibake-Cache: hit).",
        "parameters": [{"name": "Idempotency-Key", "in": "header", "schema": {"type": "string", "maxLength": 200}}],
        "requestBody": {"required": true, "content": {
          "model/gltf-binary": {"schema": {"type": "string", "format": "binary"}},
          "model/gltf+json": {"schema": {"type": "object"}},
          "multipart/form-data": {"schema": {"type": "object", "properties": {
            "scene": {"type": "string", "format": "binary"}, "params": {"type": "object"}}}}}},
        "responses": {
          "202": {"description": "Accepted", "headers": {"Location": {"schema": {"type": "string"}}},
                  "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Job"}}}},
          "200": {"description": "Same Idempotency-Key, or a cache hit", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Job"}}}},
          "400": {"description": "Bad parameters, or a form without exactly one 'scene' part (and at most one 'params' part)", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}},
          "401": {"description": "Missing or wrong bearer token (answered from the headers, before the body is read)"},
          "408": {"description": "The headers took longer than --header-timeout, or the body arrived slower than --min-rate", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}},
          "413": {"description": "Body larger than the server's --max-body (answered before the body is read)", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}},
          "431": {"description": "Request line and headers larger than 8 KB", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}},
          "415": {"description": "Unsupported content type"},
          "422": {"description": "The scene is not a usable glTF file, its images hold more pixels than --max-image-pixels, the job would need more memory than --max-job-mb, or the Idempotency-Key was used with another scene or other parameters", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}},
          "429": {"description": "Queue full", "headers": {"Retry-After": {"schema": {"type": "integer"}}}},
          "503": {"description": "Too many scenes waiting to be checked, or the job store is busy or cannot be reached (the error says which)", "headers": {"Retry-After": {"schema": {"type": "integer"}}}}}},
      "get": {
        "summary": "List jobs, newest first",
        "parameters": [
          {"name": "state", "in": "query", "schema": {"enum": ["queued", "running", "succeeded", "failed", "cancelled"]}},
          {"name": "limit", "in": "query", "schema": {"type": "integer", "minimum": 1, "maximum": 1000, "default": 50}},
          {"name": "after", "in": "query", "description": "Paging cursor: the last id of the previous page", "schema": {"type": "string"}}],
        "responses": {"200": {"description": "A page of jobs; 'next' links the following page",
          "content": {"application/json": {"schema": {"type": "object", "properties": {
            "jobs": {"type": "array", "items": {"$ref": "#/components/schemas/Job"}}, "next": {"type": "string"}}}}}},
          "503": {"$ref": "#/components/responses/StoreUnavailable"}}}
    },
    "/v1/jobs/{id}": {
      "parameters": [{"$ref": "#/components/parameters/id"}],
      "get": {"summary": "A job's state and progress", "responses": {
        "200": {"description": "The job", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Job"}}}},
        "404": {"description": "No such job"}, "503": {"$ref": "#/components/responses/StoreUnavailable"}}},
      "delete": {"summary": "Cancel a queued or running job (the worker stops within one shot, on whichever node runs it)", "responses": {
        "200": {"description": "Cancelled", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Job"}}}},
        "404": {"description": "No such job"}, "409": {"description": "Already finished"},
        "503": {"$ref": "#/components/responses/StoreUnavailable"}}}
    },
    "/v1/jobs/{id}/events": {
      "parameters": [{"$ref": "#/components/parameters/id"},
                     {"name": "Last-Event-ID", "in": "header", "schema": {"type": "string"}}],
      "get": {"summary": "Server-Sent Events: 'progress' and 'state' events with ids, a heartbeat comment, and a final 'state' event when the job ends",
        "responses": {"200": {"description": "An event stream", "content": {"text/event-stream": {}}},
                      "404": {"description": "No such job"},
                      "503": {"description": "Too many streams, or the job store is busy or cannot be reached (the error says which)", "headers": {"Retry-After": {"schema": {"type": "integer"}}}}}}
    },
    "/v1/jobs/{id}/result": {
      "parameters": [{"$ref": "#/components/parameters/id"},
                     {"name": "If-None-Match", "in": "header", "schema": {"type": "string"}}],
      "get": {"summary": "The baked GLB", "responses": {
        "200": {"description": "The result", "headers": {"ETag": {"schema": {"type": "string"}}},
                "content": {"model/gltf-binary": {"schema": {"type": "string", "format": "binary"}}}},
        "304": {"description": "Not modified"}, "404": {"description": "No such job"},
        "409": {"description": "Not finished, failed or cancelled"}, "503": {"$ref": "#/components/responses/StoreUnavailable"}}}
    },
    "/v1/jobs/{id}/preview": {
      "parameters": [{"$ref": "#/components/parameters/id"}],
      "get": {"summary": "The current, unconverged state of a running job as GLB (with the ambient term), made between two shots",
        "responses": {"200": {"description": "A preview; Server-Timing write;dur= says how many milliseconds the worker took to write it", "content": {"model/gltf-binary": {"schema": {"type": "string", "format": "binary"}}}},
                      "404": {"description": "No such job"}, "409": {"description": "The job is not running"},
                      "503": {"$ref": "#/components/responses/StoreUnavailable"}}}
    },
    "/healthz": {"get": {"summary": "Liveness", "security": [{}], "responses": {"200": {"description": "Alive"}}}},
    "/readyz": {"get": {"summary": "Readiness", "security": [{}], "responses": {"200": {"description": "Ready"}, "503": {"description": "Not ready"}}}},
    "/metrics": {"get": {"summary": "Prometheus metrics", "description": "hemibake_store_up is 0 while the job store cannot answer; the job counts (hemibake_jobs, hemibake_queue_depth) are then left out rather than given as 0, and the node's own metrics are still given", "responses": {"200": {"description": "Text exposition format", "content": {"text/plain": {}}}}}},
    "/openapi.json": {"get": {"summary": "This document", "responses": {"200": {"description": "OpenAPI 3.1"}}}}
  }
})json";

}  // namespace hemibake::server
