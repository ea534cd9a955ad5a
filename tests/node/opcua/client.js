// node-opcua as an integrator's OPC UA client of the appliance, an implementation independent of the server's
// (asyncua): it logs in over Basic256Sha256 Sign & Encrypt, browses the machine, subscribes to the result event,
// waits for one result, reads LatestResult and the units, calls the Result Transfer methods, and prints what it
// decoded as one JSON document on stdout. Structures are decoded from the DataTypeDefinitions the server
// publishes (node-opcua reads them on its own); nothing about the appliance's types is known here.
//
// usage: node client.js ENDPOINT USER PASSWORD PKI_DIR DEVICE_ID
// stdout: the line "subscribed" once the event subscription is live (the caller then starts a measurement),
// then the JSON document. Every wait is bounded; a failure prints {"error": ...} and exits 1.
"use strict";

const {
    OPCUAClient, MessageSecurityMode, SecurityPolicy, UserTokenType, AttributeIds, BrowseDirection,
    makeBrowsePath, TimestampsToReturn, ClientMonitoredItem, DataType, EventFilter, NodeClassMask,
} = require("node-opcua-client");
const { OPCUACertificateManager } = require("node-opcua-certificate-manager");

const [endpoint, userName, password, pkiDir, device] = process.argv.slice(2);
const NS = {
    machinery: "http://opcfoundation.org/UA/Machinery/",
    result: "http://opcfoundation.org/UA/Machinery/Result/",
    moi: "urn:moi:opcua",
};
const WAIT_MS = 60000;

function plain(value) {
    // an ExtensionObject or a Variant as plain JSON (NaN: null), field names as node-opcua gives them
    return JSON.parse(JSON.stringify(value, (k, v) => (typeof v === "bigint" ? Number(v)
        : ArrayBuffer.isView(v) ? Array.from(v) : v)));
}

function withTimeout(promise, ms, what) {
    let timer;
    return Promise.race([promise, new Promise((_, reject) => {
        timer = setTimeout(() => reject(new Error(`timed out after ${ms} ms waiting for ${what}`)), ms);
    })]).finally(() => clearTimeout(timer));
}

async function browse(session, nodeId, referenceTypeId = "HierarchicalReferences") {
    const r = await session.browse({
        nodeId, referenceTypeId, includeSubtypes: true, browseDirection: BrowseDirection.Forward,
        nodeClassMask: NodeClassMask.Object | NodeClassMask.Variable, resultMask: 0x3f,
    });
    return r.references.map((ref) => ({
        name: ref.browseName.name, nodeId: ref.nodeId.toString(), reference: ref.referenceTypeId.toString(),
        typeDefinition: ref.typeDefinition.toString(),
    }));
}

async function path(session, start, names) {
    const r = await session.translateBrowsePath(makeBrowsePath(start, names.map((n) => "/" + n).join("")));
    if (!r.statusCode.isGood() || !r.targets.length) throw new Error(`no node at ${names.join("/")}: ${r.statusCode}`);
    return r.targets[0].targetId;
}

async function typeDefinition(session, nodeId) {
    const refs = await session.browse({
        nodeId, referenceTypeId: "HasTypeDefinition", browseDirection: BrowseDirection.Forward, resultMask: 0x3f,
    });
    return refs.references.map((r) => r.nodeId.toString());
}

async function encodings(session, dataType) {
    // the DataType's encodings and each one's type definition (DataTypeEncodingType, i=76)
    const refs = await session.browse({
        nodeId: dataType, referenceTypeId: "HasEncoding", browseDirection: BrowseDirection.Forward, resultMask: 0x3f,
    });
    const out = {};
    for (const r of refs.references) out[r.browseName.name] = await typeDefinition(session, r.nodeId);
    return out;
}

async function units(session, parent) {
    // every component with EngineeringUnits: its EUInformation (OPC 10000-8)
    const out = {};
    for (const c of await browse(session, parent)) {
        const props = await browse(session, c.nodeId, "HasProperty");
        const eu = props.find((p) => p.name === "EngineeringUnits");
        const value = await session.read({ nodeId: c.nodeId, attributeId: AttributeIds.Value });
        out[c.name] = { typeDefinition: c.typeDefinition, value: plain(value.value.value) };
        if (eu) {
            const v = await session.read({ nodeId: eu.nodeId, attributeId: AttributeIds.Value });
            out[c.name].engineeringUnits = plain(v.value.value);
        }
    }
    return out;
}

function waitForEvent(subscription, rm, ns, resultReadyType) {
    // EventType, Message, Severity and ResultReadyEventType's Result (OPC 40001-101)
    const field = (type, name, index = 0) => ({
        typeDefinitionId: type, browsePath: [{ namespaceIndex: index, name }], attributeId: AttributeIds.Value,
    });
    const filter = new EventFilter({
        selectClauses: [field("i=2041", "EventType"), field("i=2041", "Message"), field("i=2041", "Severity"),
            field(resultReadyType, "Result", ns.result)],
    });
    return new Promise((resolve, reject) => {
        const item = ClientMonitoredItem.create(subscription,
            { nodeId: rm, attributeId: AttributeIds.EventNotifier },
            { queueSize: 10, filter, discardOldest: false, samplingInterval: 0 }, TimestampsToReturn.Neither);
        item.on("initialized", () => process.stdout.write("subscribed\n"));
        item.on("err", (e) => reject(new Error(`event subscription: ${e}`)));
        item.on("changed", (fields) => resolve({
            eventType: fields[0].value.toString(), message: fields[1].value && fields[1].value.text,
            severity: fields[2].value, resultDataType: fields[3].dataType === DataType.ExtensionObject,
            result: plain(fields[3].value),
        }));
    });
}

async function call(session, object, method, inputs) {
    const r = await session.call({ objectId: object, methodId: method, inputArguments: inputs });
    return { status: r.statusCode.name, outputs: r.outputArguments.map((v) => plain(v.value)) };
}

async function main() {
    const certificateManager = new OPCUACertificateManager({
        rootFolder: pkiDir, automaticallyAcceptUnknownCertificate: true,
    });
    await certificateManager.initialize();
    const client = OPCUAClient.create({
        applicationName: "moi-node-opcua-test", applicationUri: "urn:moi-test:node-opcua",
        securityMode: MessageSecurityMode.SignAndEncrypt, securityPolicy: SecurityPolicy.Basic256Sha256,
        endpointMustExist: false, connectionStrategy: { maxRetry: 0 }, requestedSessionTimeout: 60000,
        clientCertificateManager: certificateManager,
    });
    await client.connect(endpoint);
    const session = await client.createSession({ type: UserTokenType.UserName, userName, password });
    try {
        const array = await session.readNamespaceArray();
        const ns = Object.fromEntries(Object.entries(NS).map(([k, uri]) => [k, array.indexOf(uri)]));
        const machine = await path(session, "ObjectsFolder", [`${ns.machinery}:Machines`, `${ns.moi}:${device}`]);
        const blocks = await path(session, machine, [`${ns.machinery}:MachineryBuildingBlocks`]);
        const rm = await path(session, blocks, [`${ns.result}:ResultManagement`]);
        const results = await path(session, rm, [`${ns.result}:Results`]);
        const resultReadyType = `ns=${ns.result};i=1002`;
        const out = { namespaces: ns, buildingBlocks: await browse(session, blocks, "HasAddIn"),
            results: await browse(session, results) };

        const subscription = await session.createSubscription2({
            requestedPublishingInterval: 50, requestedLifetimeCount: 600, requestedMaxKeepAliveCount: 20,
            publishingEnabled: true,
        });
        out.event = await withTimeout(waitForEvent(subscription, rm, ns, resultReadyType), WAIT_MS, "ResultReadyEvent");
        await subscription.terminate();

        const latest = await path(session, results, [`${ns.result}:LatestResult`]);
        out.latestResult = {
            typeDefinition: await typeDefinition(session, latest),
            dataType: (await session.read({ nodeId: latest, attributeId: AttributeIds.DataType })).value.value.toString(),
            value: plain((await session.read({ nodeId: latest, attributeId: AttributeIds.Value })).value.value),
        };
        const content = await path(session, latest, [`${ns.result}:ResultContent`]);
        out.contentVariable = plain((await session.read({ nodeId: content, attributeId: AttributeIds.Value })).value.value);
        out.components = await units(session, content);
        out.encodings = {
            ResultDataType: await encodings(session, `ns=${ns.result};i=3008`),
            InertiaResultDataType: await encodings(session, `ns=${ns.moi};s=InertiaResultDataType`),
        };
        out.eventResultTypeDefinition = await typeDefinition(session, `ns=${ns.result};i=6032`);
        out.itemStates = await browse(session, `ns=${ns.machinery};i=1002`);  // MachineryItemState_StateMachineType

        const method = async (name) => path(session, rm, [`${ns.result}:${name}`]);
        const resultId = out.event.result.resultMetaData.resultId;
        out.getLatestResult = await call(session, rm, await method("GetLatestResult"),
            [{ dataType: DataType.Int32, value: 0 }]);
        out.getResultById = await call(session, rm, await method("GetResultById"),
            [{ dataType: DataType.String, value: resultId }, { dataType: DataType.Int32, value: 0 }]);
        out.getUnknownResult = await call(session, rm, await method("GetResultById"),
            [{ dataType: DataType.String, value: "no-such-result" }, { dataType: DataType.Int32, value: 0 }]);
        out.acknowledgeResults = await call(session, rm, await method("AcknowledgeResults"),
            [{ dataType: DataType.String, arrayType: 1, value: [resultId] }]);
        process.stdout.write(JSON.stringify(out) + "\n");
    } finally {
        await session.close();
        await client.disconnect();
        await certificateManager.dispose();
    }
}

withTimeout(main(), 2 * WAIT_MS, "the client").then(() => process.exit(0), (e) => {
    process.stdout.write(JSON.stringify({ error: String(e && e.stack || e) }) + "\n");
    process.exit(1);
});
